// SPDX-License-Identifier: Apache-2.0
#pragma once

// The plumb-backend command line (also behind `plumb replay`): ingest live over LCM, from an LCM
// log or from a fragment store (backend/ingest/ingest_run.hpp), then the reconstruction
// pipeline when this build has one. Installs SIGINT/SIGTERM handlers that stop a live ingest.
//
// Thread-safety: call from the main thread, one call at a time: it installs process-wide signal
// handlers (again on every call).

#include <string>
#include <vector>

namespace plumb::backend {

/// Runs the command with `args` (without the program name); returns the exit code: 0 done,
/// 1 failed (or timed out), 2 bad command line. `program` names the command in messages.
int runBackendCommand(std::vector<std::string> args, const char* program);

}  // namespace plumb::backend
