// The whole rouen CLI (every command), as the librouen_cli module runs it.
#pragma once

namespace rouen {

// Registers every command, parses argv and runs the chosen one; returns the exit status.
int RunCli(int argc, char** argv);

}  // namespace rouen

extern "C" {
// librouen_cli's entry point (dlsym name "rouen_cli_main"): RunCli.
int rouen_cli_main(int argc, char** argv);
}
