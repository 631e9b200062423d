#include <gtest/gtest.h>

#include <fstream>

#include "exe/args.h"
#include "util/check.h"
#include "util/file.h"
#include "util/logging.h"
#include "util/string_util.h"

namespace arpos {
namespace {

TEST(Check, ThrowsWithLocationAndMessage) {
  try {
    ARPOS_CHECK(1 + 1 == 3, "arithmetic is broken: " << 42);
    FAIL() << "no throw";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("arithmetic is broken: 42"), std::string::npos);
    EXPECT_NE(what.find("util_test.cc"), std::string::npos);
  }
}

TEST(StringUtil, ParsesStrictly) {
  double d = 0;
  EXPECT_TRUE(ParseDouble("1.5e-3", &d));
  EXPECT_DOUBLE_EQ(d, 1.5e-3);
  EXPECT_FALSE(ParseDouble("1.5x", &d));
  EXPECT_FALSE(ParseDouble("", &d));
  EXPECT_FALSE(ParseDouble("nan", &d));
  long long i = 0;
  EXPECT_TRUE(ParseInt("-12", &i));
  EXPECT_EQ(i, -12);
  EXPECT_FALSE(ParseInt("1.0", &i));
  EXPECT_EQ(SplitWhitespace("  a \t b  c\n").size(), 3u);
  EXPECT_EQ(Trim("  x y \n"), "x y");
}

TEST(StringUtil, AClauseBecomesASentence) {
  EXPECT_EQ(AsSentence("with this room map no frame can read `in`"),
            "With this room map no frame can read `in`.");
  EXPECT_EQ(AsSentence(""), "");
}

TEST(File, AtomicWriteReplacesWholeFile) {
  TempDir dir;
  const auto path = dir.path() / "f.txt";
  WriteFileAtomic(path, "first version, long");
  WriteFileAtomic(path, "second");
  EXPECT_EQ(ReadTextFile(path), "second");
  size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.path())) files += e.is_regular_file();
  EXPECT_EQ(files, 1u);  // no temporary left behind
  EXPECT_THROW(ReadTextFile(dir.path() / "missing.txt"), InputError);
}

TEST(Logging, SinkReceivesAtOrAboveLevel) {
  std::vector<std::string> got;
  const auto previous = SetLogSink([&](LogLevel, const std::string& m) { got.push_back(m); });
  const LogLevel old = GetLogLevel();
  SetLogLevel(LogLevel::kWarning);
  ARPOS_INFO("hidden");
  ARPOS_WARN("shown " << 1);
  SetLogLevel(old);
  SetLogSink(previous);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0], "shown 1");
}

TEST(Args, ParsesOptionsAndRejectsUnknown) {
  const Args args({"case", "--store", "x.db", "--json", "--max-dt=0.5"}, {"store", "max-dt"},
                  {"json"});
  EXPECT_EQ(args.positional(), std::vector<std::string>{"case"});
  EXPECT_EQ(args.Require("store"), "x.db");
  EXPECT_TRUE(args.Has("json"));
  EXPECT_DOUBLE_EQ(args.GetDouble("max-dt", 0), 0.5);
  EXPECT_THROW(Args({"--bogus"}, {}, {}), InputError);
  EXPECT_THROW(Args({"--store"}, {"store"}, {}), InputError);
  EXPECT_THROW(args.Require("gt"), InputError);
}

}  // namespace
}  // namespace arpos
