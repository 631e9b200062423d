// Camera-source plugins loaded as the executable loads them.
#include <gtest/gtest.h>

#include <fstream>

#include "sensor/camera_source.h"
#include "sensor/source_plugin.h"
#include "sensor/test_case_builder.h"
#include "util/check.h"
#include "util/file.h"

namespace arpos {
namespace {

std::vector<SourcePluginLoad> LoadBuilt(CameraSourceRegistry* registry) {
  return LoadSourcePlugins(registry, {ARPOS_PLUGIN_DIR});
}

TEST(SourcePlugins, EveryBuiltPluginLoadsAndRegistersItsKinds) {
  CameraSourceRegistry registry;
  const auto loads = LoadBuilt(&registry);
  ASSERT_FALSE(loads.empty());
  for (const auto& load : loads) EXPECT_TRUE(load.loaded) << load.path << ": " << load.error;
  EXPECT_TRUE(registry.Has("replay"));
  for (const auto& kind : registry.Kinds()) {
    EXPECT_FALSE(kind.help.empty()) << kind.name;
    EXPECT_NE(kind.origin.find("libarpos_source_"), std::string::npos) << kind.name;
  }
}

TEST(SourcePlugins, ReplayDeliversEveryFrameAndSaysWhatIsWrongWithOne) {
  CameraSourceRegistry registry;
  LoadBuilt(&registry);
  TempDir dir;
  testing::WriteTinyCase(dir.path());
  // Frame 1's colour is broken: delivered, with the problem named.
  std::filesystem::path broken;
  for (const auto& e : std::filesystem::directory_iterator(dir.path() / "tracking" / "a" / "rgb")) {
    if (broken.empty() || e.path() < broken) broken = e.path();
  }
  std::ofstream(broken, std::ios::trunc) << "not a png";
  auto source = registry.Create("replay:" + (dir.path() / "tracking" / "a").string());
  EXPECT_EQ(source->frame_count(), 3);
  EXPECT_FALSE(source->live());
  source->Open();
  RgbdFrame frame;
  int n = 0, problems = 0;
  while (source->Next(&frame)) {
    EXPECT_EQ(frame.index, n);
    if (!frame.problem.empty()) {
      ++problems;
      EXPECT_TRUE(frame.color.empty());
      EXPECT_NE(frame.problem.find(broken.filename().string()), std::string::npos) << frame.problem;
    } else {
      EXPECT_EQ(frame.color.type(), CV_8UC3);
      EXPECT_EQ(frame.depth.type(), CV_16UC1);
    }
    ++n;
  }
  EXPECT_EQ(n, 3);
  EXPECT_EQ(problems, 1);
  EXPECT_EQ(source->frames_delivered(), 3);
  source->Close();
  EXPECT_FALSE(source->Next(&frame));
  EXPECT_THROW(registry.Create("replay:" + dir.path().string() + "/../nowhere"), InputError);
  EXPECT_THROW(registry.Create("replay:" + (dir.path() / "tracking" / "a").string() + "?fast"), InputError);
  EXPECT_THROW(registry.Create("replay"), InputError);
}

TEST(SourcePlugins, AnUnknownKindNamesTheKnownOnes) {
  CameraSourceRegistry registry;
  LoadBuilt(&registry);
  try {
    registry.Create("firewire:0");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("replay"), std::string::npos) << e.what();
  }
  CameraSourceRegistry empty;
  try {
    empty.Create("replay:x");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no plugin was loaded"), std::string::npos) << e.what();
  }
}

TEST(SourcePlugins, ABadPluginIsReportedNotLoaded) {
  TempDir dir;
  // Not a shared library at all.
  std::ofstream(dir.path() / "libarpos_source_garbage.so") << "garbage";
  // Not a plugin's name: ignored.
  std::ofstream(dir.path() / "notes.txt") << "x";
  CameraSourceRegistry registry;
  const auto loads = LoadSourcePlugins(&registry, {dir.path(), ARPOS_BAD_PLUGIN_DIR, dir.path() / "absent"});
  ASSERT_EQ(loads.size(), 2u);
  for (const auto& load : loads) EXPECT_FALSE(load.loaded);
  const auto find = [&](const std::string& name) {
    for (const auto& load : loads) {
      if (load.path.filename() == name) return load.error;
    }
    return std::string("(not reported)");
  };
  EXPECT_FALSE(find("libarpos_source_garbage.so").empty());
  EXPECT_NE(find("libarpos_source_wrongversion.so").find("plugin API"), std::string::npos)
      << find("libarpos_source_wrongversion.so");
  EXPECT_TRUE(registry.Kinds().empty());
}

}  // namespace
}  // namespace arpos
