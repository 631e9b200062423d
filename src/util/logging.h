#pragma once
/// Logging facade. Library code logs through here and never writes to stderr
/// itself; the executable installs a sink (stderr by default for the CLI, a
/// panel in the GUI). Thread-safe.

#include <functional>
#include <sstream>
#include <string>

namespace arpos {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarning = 2, kError = 3 };

using LogSink = std::function<void(LogLevel, const std::string&)>;

/// Replaces the sink; nullptr silences logging. Returns the previous sink.
LogSink SetLogSink(LogSink sink);
/// Messages below this level are dropped before formatting reaches the sink.
void SetLogLevel(LogLevel level);
LogLevel GetLogLevel();
void Log(LogLevel level, const std::string& message);
const char* LogLevelName(LogLevel level);

}  // namespace arpos

#define ARPOS_LOG(level, msg)                                           \
  do {                                                                  \
    if (static_cast<int>(level) >= static_cast<int>(::arpos::GetLogLevel())) { \
      std::ostringstream arpos_log_stream_;                             \
      arpos_log_stream_ << msg;                                         \
      ::arpos::Log(level, arpos_log_stream_.str());                     \
    }                                                                   \
  } while (false)
#define ARPOS_INFO(msg) ARPOS_LOG(::arpos::LogLevel::kInfo, msg)
#define ARPOS_WARN(msg) ARPOS_LOG(::arpos::LogLevel::kWarning, msg)
#define ARPOS_DEBUG(msg) ARPOS_LOG(::arpos::LogLevel::kDebug, msg)
