#pragma once
/// Human-readable summaries of a store, for `arpos store info` and logs.
///
/// Thread-safety: as the Database passed in (one thread at a time).

#include <cstddef>
#include <cstdint>
#include <string>

#include "store/database.h"

namespace arpos {

/// A multi-line summary: file, schema version (and the program's), journal
/// mode, size, rows per table, and the newest `max_listed` plans and sessions.
/// Ends with a newline. Reads only.
std::string DescribeStore(Database& database, std::size_t max_listed = 5);

/// "2024-05-01 12:34:56 UTC" for a time in milliseconds since the epoch.
std::string FormatUtcTime(std::int64_t unix_ms);

}  // namespace arpos
