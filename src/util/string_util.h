#pragma once
/// Small string helpers.

#include <string>
#include <string_view>
#include <vector>

namespace arpos {

std::string Trim(std::string_view text);
/// Splits on any run of whitespace; no empty tokens.
std::vector<std::string> SplitWhitespace(std::string_view text);
bool StartsWith(std::string_view text, std::string_view prefix);
bool EndsWith(std::string_view text, std::string_view suffix);
std::string ToLower(std::string_view text);
/// A clause as a sentence of its own: first letter upper case, a full stop
/// at the end ("with this map ..." -> "With this map ...."); "" stays "".
std::string AsSentence(std::string_view clause);
/// Strict number parsing: the whole token must be a finite number.
bool ParseDouble(std::string_view token, double* value);
bool ParseInt(std::string_view token, long long* value);
/// printf-style formatting into a std::string.
std::string StringPrintf(const char* format, ...) __attribute__((format(printf, 1, 2)));

}  // namespace arpos
