// `arpos import-model`: in-process for speed, plus one run of the real executable.
#include <gtest/gtest.h>

#include <cstdlib>
#include <sstream>

#include "exe/cmd_import_model.h"
#include "geometry/mesh_io.h"
#include "model_import/test_util.h"
#include "util/file.h"

namespace arpos {
namespace {

struct CommandRun {
  int status;
  std::string out, err;
};

CommandRun Command(const std::vector<std::string>& args) {
  std::ostringstream out, err;
  const int status = RunImportModelCommandWithOutput(args, out, err);
  return {status, out.str(), err.str()};
}

TEST(ImportModelCommand, MeshInMillimetresReportsAndWritesMetres) {
  TempDir dir;
  SaveTriangleMeshPly(test::Scaled(test::Ellipsoid({0.2, 0.12, 0.45}, {0, 0, 0}), 1000.0),
                      dir.path() / "torso_mm.ply");
  const fs::path out = dir.path() / "model.ply";
  const CommandRun run = Command({(dir.path() / "torso_mm.ply").string(), "--out", out.string()});
  ASSERT_EQ(run.status, 0) << run.err;
  EXPECT_NE(run.out.find("units:     mm (detected"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("extent:    400.0 x 240.0 x 900.0 mm"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("closed:    yes, 1 component"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("area:"), std::string::npos) << run.out;
  const TriangleMesh model = LoadTriangleMesh(out, 1.0);
  Eigen::Vector3f lo, hi;
  model.Bounds(&lo, &hi);
  EXPECT_NEAR(hi.z() - lo.z(), 0.9, 1e-4);
  EXPECT_TRUE(model.IsClosed());
}

TEST(ImportModelCommand, RtStructReportsRoiFrameAndCloseness) {
  TempDir dir;
  const fs::path out = dir.path() / "body.ply";
  const CommandRun run = Command({test::RtStructFile().string(), "--out", out.string(), "--max-vertices", "20000",
                                  "--roi", "heart", "--origin", "isocentre", "--rtplan", test::RtPlanFile().string()});
  ASSERT_EQ(run.status, 0) << run.err;
  EXPECT_NE(run.out.find("roi:       'Heart' (ORGAN), chosen by named with --roi"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("origin at the RTPLAN isocentre"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("closed:    yes"), std::string::npos) << run.out;
  const TriangleMesh model = LoadTriangleMesh(out, 1.0);
  EXPECT_LE(model.vertices.size(), 20000u);
  const std::string header = test::ReadBytes(out).substr(0, 600);
  EXPECT_NE(header.find("comment frame: DICOM patient (LPS) axes, metres, origin RTPLAN isocentre"),
            std::string::npos)
      << header;
}

TEST(ImportModelCommand, UsageAndInputErrors) {
  TempDir dir;
  EXPECT_EQ(Command({"--help"}).status, 0);
  EXPECT_EQ(Command({}).status, 2);
  EXPECT_EQ(Command({test::MakeHumanObj().string()}).status, 2);  // no --out
  const CommandRun units = Command({test::MakeHumanObj().string(), "--out", "x.ply", "--units", "inch"});
  EXPECT_EQ(units.status, 2);
  EXPECT_NE(units.err.find("--units must be mm, cm, dm or m"), std::string::npos) << units.err;
  const CommandRun absurd = Command({test::MakeHumanObj().string(), "--out", (dir.path() / "x.ply").string(),
                              "--units", "m"});  // 16.9 m tall
  EXPECT_EQ(absurd.status, 2);
  EXPECT_NE(absurd.err.find("base.obj"), std::string::npos) << absurd.err;
  EXPECT_FALSE(fs::exists(dir.path() / "x.ply"));
  const CommandRun unknown = Command({test::MakeHumanObj().string(), "--out", "x.ply", "--colour", "red"});
  EXPECT_EQ(unknown.status, 2);
  EXPECT_NE(unknown.err.find("--colour"), std::string::npos);
}

TEST(ImportModelCommand, ExecutableDispatchesIt) {
  TempDir dir;
  const std::string command = std::string(ARPOS_EXECUTABLE) + " import-model " + test::MakeHumanObj().string() +
                              " --group body --out " + (dir.path() / "mh.ply").string() + " > " +
                              (dir.path() / "out.txt").string() + " 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0) << test::ReadBytes(dir.path() / "out.txt");
  const std::string out = test::ReadBytes(dir.path() / "out.txt");
  EXPECT_NE(out.find("units:     dm (detected"), std::string::npos) << out;
  EXPECT_TRUE(fs::exists(dir.path() / "mh.ply"));
}

}  // namespace
}  // namespace arpos
