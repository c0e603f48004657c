#include "app/command_list.h"

#include <unistd.h>

#include <cstdio>
#include <exception>
#include <filesystem>
#include <regex>
#include <stdexcept>
#include <string>

#include "app/commands.h"
#include "core/error.h"

namespace rouen {

const char* CommandSummary(std::string_view name) {
  for (const CommandInfo& c : kCommands) {
    if (name == c.name) return c.summary;
  }
  throw std::logic_error("app/command_list.h has no command \"" + std::string(name) + "\"");
}

void DescribeRouen(CLI::App& app) {
  app.description(
      "rouen — capture a building, its sun, sky and landscape at a few times of day, recover\n"
      "lighting and reflectance (Yu & Malik 1998), and render it at any other time.\n"
      "Run `rouen demo` for the whole pipeline on a simulated world (no hardware needed).");
  app.require_subcommand(1);
  app.set_help_all_flag("--help-all", "Show help for every subcommand");
}

namespace {

// A message as the user should read it: this process's temporary names (core/files.h
// TempPathFor, "<path>.tmp-<pid>-<n><extension>") replaced by the file they become.
std::string ForTheUser(const std::string& message) {
  static const std::regex temporary("\\.tmp-" + std::to_string(::getpid()) +
                                    "-[0-9]+(\\.[A-Za-z0-9]+)?");
  return std::regex_replace(message, temporary, "");
}

}  // namespace

int ParseAndRun(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const ExitStatus& e) {
    return e.code;
  } catch (const Error& e) {
    std::fprintf(stderr, "rouen: error: %s\n", ForTheUser(e.what()).c_str());
    return 1;
  } catch (const std::filesystem::filesystem_error& e) {
    // A disk problem (read-only, full, a file where a folder belongs): the message names it.
    std::fprintf(stderr, "rouen: error: %s\n", ForTheUser(e.what()).c_str());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "rouen: internal error: %s\n", ForTheUser(e.what()).c_str());
    return 2;
  }
  return 0;
}

}  // namespace rouen
