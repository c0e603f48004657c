// The whole rouen CLI: every command registered, parsed and run. It is built into the
// librouen_cli module, which app/main.cc loads for every command but the light ones.
#include "app/cli.h"

#include "app/command_list.h"
#include "app/commands.h"
#include "core/temporaries.h"

namespace rouen {

int RunCli(int argc, char** argv) {
  CLI::App app;
  DescribeRouen(app);
  RegisterDemo(app);
  RegisterCapture(app);
  RegisterDevices(app);
  RegisterCalib(app);
  RegisterHdr(app);
  RegisterSun(app);
  RegisterImport(app);
  RegisterStatus(app);
  RegisterSky(app);
  RegisterSolve(app);
  RegisterRender(app);
  RegisterValidate(app);
  RegisterReport(app);
  RegisterExport(app);
  RegisterEnvmap(app);
  RegisterView(app);
  RegisterTimelapse(app);
  RegisterPlan(app);
  // Ctrl-C or SIGTERM removes the temporaries of the files being written.
  RemoveTemporariesOnSignal();
  return ParseAndRun(app, argc, argv);
}

}  // namespace rouen

// The module's entry point, looked up by name with dlsym (app/main.cc).
extern "C" __attribute__((visibility("default"))) int rouen_cli_main(int argc, char** argv) {
  return rouen::RunCli(argc, argv);
}
