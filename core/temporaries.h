// Temporaries removed on every exit path, signals included. rouen writes files under
// temporary names beside their targets (core/files.h TempPathFor: "<path>.tmp-<pid>-<n>...")
// and builds some folders under one ("<dir>.tmp-<pid>", as `rouen import` does), renaming
// them into place when whole. An error unwinds and removes its own temporaries; a signal
// does not unwind, so the folders temporaries are made in are recorded here and a handler
// removes this process's temporaries from them.
#pragma once

#include <filesystem>

namespace rouen {

// Records a folder this process makes temporaries in (kept for the life of the process;
// recording one twice is harmless). Throws rouen::Error past 64 folders.
void WatchForTemporaries(const std::filesystem::path& dir);

// Installs handlers for SIGINT, SIGTERM and SIGHUP (signals that are ignored stay ignored)
// that remove this process's temporaries from the recorded folders, then re-raise the
// signal with its default action, so the process ends as the signal says.
void RemoveTemporariesOnSignal();

// What the handler does (async-signal-safe): removes every entry of the recorded folders
// named "*.tmp-<pid>" or "*.tmp-<pid>-*" for this process's pid, folders with their contents.
void RemoveOwnTemporaries();

}  // namespace rouen
