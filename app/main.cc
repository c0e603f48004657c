// rouen: capture and relight architecture (Yu & Malik 1998).
#include <cstdio>
#include <exception>
#include <filesystem>

#include "app/commands.h"
#include "core/error.h"
#include "core/temporaries.h"

int main(int argc, char** argv) {
  CLI::App app{
      "rouen — capture a building, its sun, sky and landscape at a few times of day, recover\n"
      "lighting and reflectance (Yu & Malik 1998), and render it at any other time.\n"
      "Run `rouen demo` for the whole pipeline on a simulated world (no hardware needed)."};
  app.require_subcommand(1);
  app.set_help_all_flag("--help-all", "Show help for every subcommand");
  rouen::RegisterDemo(app);
  rouen::RegisterCapture(app);
  rouen::RegisterDevices(app);
  rouen::RegisterCalib(app);
  rouen::RegisterHdr(app);
  rouen::RegisterSun(app);
  rouen::RegisterImport(app);
  rouen::RegisterStatus(app);
  rouen::RegisterSky(app);
  rouen::RegisterSolve(app);
  rouen::RegisterRender(app);
  rouen::RegisterValidate(app);
  rouen::RegisterReport(app);
  rouen::RegisterExport(app);
  rouen::RegisterEnvmap(app);
  rouen::RegisterView(app);
  rouen::RegisterTimelapse(app);
  rouen::RegisterPlan(app);
  // Ctrl-C or SIGTERM removes the temporaries of the files being written.
  rouen::RemoveTemporariesOnSignal();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const rouen::ExitStatus& e) {
    return e.code;
  } catch (const rouen::Error& e) {
    std::fprintf(stderr, "rouen: error: %s\n", e.what());
    return 1;
  } catch (const std::filesystem::filesystem_error& e) {
    // A disk problem (read-only, full, a file where a folder belongs): the message names it.
    std::fprintf(stderr, "rouen: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "rouen: internal error: %s\n", e.what());
    return 2;
  }
  return 0;
}
