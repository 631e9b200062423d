#pragma once
/// `arpos store ...`: inspect the session store; `arpos audit ...`: check
/// its audit log.
///
///   arpos store info [--store DB]    summary of the store (see store/describe.h)
///   arpos store --help
///   arpos audit verify [--store DB]  the audit log's hash chain, triggers and
///                                    coverage (store/audit_chain.h); exit 0
///                                    verified, 1 not, 2 usage or store error
///
/// DB defaults to DefaultStorePath() (store/store_path.h: $ARPOS_STORE, else
/// ./arpos_store.db). `info` never creates a store: a missing file is an error.
/// Opening an older store migrates it (as every command that opens a store
/// does); a store newer than this program is refused and left untouched.

#include <ostream>
#include <string>
#include <vector>

namespace arpos {

/// `args` are the words after `arpos store` (e.g. {"info", "--store", "a.db"}).
/// Prints results to stdout, errors to stderr. Returns 0 on success, 2 on a
/// usage or input error (bad arguments, no store at the path, a store newer
/// than this program, not an ARPos store, a problem of the file such as a
/// read-only file or folder: StoreAccessError), 1 if the store could not be read.
int RunStoreCommand(const std::vector<std::string>& args);

/// The same, writing to the given streams (for tests). A separate name, so
/// that `RunStoreCommand` stays a single function the dispatcher can take.
int RunStoreCommandWithOutput(const std::vector<std::string>& args, std::ostream& out,
                              std::ostream& err);

/// `arpos audit ...` (the words after `arpos audit`), as RunStoreCommand.
int RunAuditCommand(const std::vector<std::string>& args);
int RunAuditCommandWithOutput(const std::vector<std::string>& args, std::ostream& out,
                              std::ostream& err);

}  // namespace arpos
