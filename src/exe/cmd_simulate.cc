#include "exe/cmd_simulate.h"

#include <algorithm>
#include <array>
#include <cstdlib>
#include <iostream>

#include "exe/args.h"
#include "simulation/simulator.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace {

const char kUsage[] =
    "usage: arpos simulate OUT_DIR [options]\n"
    "\n"
    "Writes a synthetic treatment session (case folder, DATASET.md) with exact ground\n"
    "truth: room/, body_scan/, tracking/seq_NN/, reference_model.ply, target_pose.txt,\n"
    "case.yaml and simulation.yaml (marker truth, isocentre, hard effects).\n"
    "\n"
    "options:\n"
    "  --profile xtion|l515|d435   camera (default xtion: 640x480; l515: 1280x720;\n"
    "                              d435: 848x480, off-centre principal point)\n"
    "  --seed N                    random seed (default 1); same seed, same bytes\n"
    "  --hard                      motion blur, lighting change, a hand over the\n"
    "                              stickers, a sticker that falls off\n"
    "  --frames room=N,body=N,tracking=N   frames per sequence (default 300,150,150)\n"
    "  --tracking-sequences K      number of tracking sequences (default 2)\n"
    "  --room-walk full|couch      planning walk: the couch and every wall (default),\n"
    "                              or around the couch only (small cases)\n"
    "  --room-texture rich|plain   the room's surfaces: posters, signs and clutter\n"
    "                              (default), or plain paint, tile seams and the\n"
    "                              gantry's panels (few keypoints)\n"
    "  --no-noise                  exact renders: no blur, noise or depth dropouts\n"
    "  --body-mesh PATH            MakeHuman base.obj (default: $ARPOS_BODY_MESH or the\n"
    "                              shared data copy)\n"
    "  --png-compression 0..9      PNG compression level (default 1)\n"
    "  --supersampling S           colour samples per pixel axis: 1, 3 or 5 (default 3)\n"
    "\n"
    "sensor and patient conditions (default: none of them; all recorded in simulation.yaml):\n"
    "  --response NAME             colour camera response: srgb (default), linear,\n"
    "                              gamma2.6 (y = x^(1/2.6)), scurve (sRGB then a contrast\n"
    "                              S-curve with toe and shoulder); see camera_response.h\n"
    "  --auto-exposure             exposure drifting smoothly by up to +-1 stop, applied\n"
    "                              before the response (bright parts clip at 255)\n"
    "  --sharpen A                 the camera sharpens its encoded image: code + A * (code -\n"
    "                              Gaussian(code, 1 px)), as consumer cameras do (0..3)\n"
    "  --depth-scale-error F       depth reads F too long (0.003 = +0.3 %)\n"
    "  --depth-field-mm A          smooth depth error field over the image, A mm at 1 m\n"
    "                              (growing with depth squared)\n"
    "  --flying-pixels             depths between the two surfaces at depth edges\n"
    "  --depth-delay-ms MS         each depth image captured MS after its colour image\n"
    "                              (a camera without colour-depth sync; within +-15), listed\n"
    "                              in depth.txt at its own timestamp\n"
    "  --distortion K1,K2,P1,P2,K3  lens distortion of the colour camera (OpenCV model; the\n"
    "                              depth is registered to it), e.g. a Kinect's\n"
    "                              0.26,-0.95,-0.005,0.003,1.16; written to case.yaml\n"
    "  --dictionary NAME           ArUco dictionary of every marker (default DICT_4X4_250;\n"
    "                              any OpenCV predefined one with 200 markers or more)\n"
    "  --sticker-size-m S          printed side of the body stickers (default 0.03)\n"
    "  --breathing-mm A            the anterior torso moves A mm peak to peak (period 3-5 s);\n"
    "                              the reference model and body ground truth are end-exhale\n"
    "  --random-conditions         draw the scene from the seed: origin marker placement\n"
    "                              (floor near the couch, farther, on a wall), its\n"
    "                              visibility (good, medium, poor: a few glancing views),\n"
    "                              room marker count and size, room size, walk and pace,\n"
    "                              response, auto exposure, depth bias, breathing,\n"
    "                              colour-depth sync; the options above force a condition\n"
    "                              over the drawn one\n";

void ParseFrames(const std::string& text, sim::SimulationOptions* options) {
  size_t start = 0;
  while (start <= text.size()) {
    size_t end = text.find(',', start);
    if (end == std::string::npos) end = text.size();
    const std::string item = Trim(text.substr(start, end - start));
    const size_t eq = item.find('=');
    long long value = 0;
    if (eq == std::string::npos || !ParseInt(item.substr(eq + 1), &value) || value < 1) {
      ARPOS_INPUT_ERROR("--frames: expected room=N,body=N,tracking=N with N >= 1, got '" << text
                                                                                      << "'");
    }
    const std::string key = item.substr(0, eq);
    if (key == "room") {
      options->room_frames = static_cast<int>(value);
    } else if (key == "body" || key == "body_scan") {
      options->body_scan_frames = static_cast<int>(value);
    } else if (key == "tracking") {
      options->tracking_frames = static_cast<int>(value);
    } else {
      ARPOS_INPUT_ERROR("--frames: unknown sequence '" << key << "' (room, body, tracking)");
    }
    start = end + 1;
  }
}

}  // namespace

int RunSimulateCommand(const std::vector<std::string>& argv) {
  try {
    for (const auto& a : argv) {
      if (a == "--help" || a == "-h") {
        std::cout << kUsage;
        return 0;
      }
    }
    const Args args(argv,
                    {"profile", "seed", "frames", "tracking-sequences", "room-walk", "room-texture",
                     "body-mesh", "png-compression", "supersampling", "response",
                     "depth-scale-error", "depth-field-mm", "breathing-mm", "distortion",
                     "dictionary", "sticker-size-m", "sharpen", "depth-delay-ms"},
                    {"hard", "no-noise", "auto-exposure", "flying-pixels", "random-conditions"});
    if (args.positional().size() != 1) {
      std::cerr << "simulate: expected one OUT_DIR\n" << kUsage;
      return 2;
    }
    sim::SimulationOptions options;
    options.profile = args.GetOr("profile", "xtion");
    const long long seed = args.GetInt("seed", 1);
    if (seed < 0) ARPOS_INPUT_ERROR("--seed: must be non-negative, got " << seed);
    options.seed = static_cast<uint64_t>(seed);
    options.hard = args.Has("hard");
    options.noise = !args.Has("no-noise");
    if (auto frames = args.Get("frames")) ParseFrames(*frames, &options);
    options.tracking_sequences = static_cast<int>(args.GetInt("tracking-sequences", 2));
    options.room_walk = args.GetOr("room-walk", "full");
    options.room_texture = args.GetOr("room-texture", "rich");
    if (auto mesh = args.Get("body-mesh")) options.body_mesh_path = *mesh;
    options.png_compression = static_cast<int>(args.GetInt("png-compression", 1));
    options.supersampling = static_cast<int>(args.GetInt("supersampling", 0));
    if (auto response = args.Get("response")) options.response = *response;
    if (args.Has("auto-exposure")) options.auto_exposure = true;
    if (args.Has("depth-scale-error")) options.depth_scale_error = args.GetDouble("depth-scale-error", 0);
    if (args.Has("depth-field-mm")) options.depth_field_mm = args.GetDouble("depth-field-mm", 0);
    if (args.Has("flying-pixels")) options.flying_pixels = true;
    if (args.Has("breathing-mm")) options.breathing_mm = args.GetDouble("breathing-mm", 0);
    if (args.Has("sharpen")) options.sharpen_amount = args.GetDouble("sharpen", 0);
    if (args.Has("depth-delay-ms"))
      options.depth_delay_s = args.GetDouble("depth-delay-ms", 0) / 1000;
    if (auto d = args.Get("distortion")) {
      std::string spaced = *d;
      std::replace(spaced.begin(), spaced.end(), ',', ' ');
      const std::vector<std::string> parts = SplitWhitespace(spaced);
      std::array<double, 5> k{};
      if (parts.size() != 5) ARPOS_INPUT_ERROR("--distortion: expected k1,k2,p1,p2,k3 (5 numbers), got '" << *d << "'");
      for (int i = 0; i < 5; ++i) {
        char* end = nullptr;
        k[i] = std::strtod(parts[i].c_str(), &end);
        if (end == parts[i].c_str() || *end != '\0') ARPOS_INPUT_ERROR("--distortion: '" << parts[i] << "' is not a number");
      }
      options.distortion = k;
    }
    options.dictionary = args.GetOr("dictionary", "DICT_4X4_250");
    options.sticker_size_m = args.GetDouble("sticker-size-m", 0.03);
    options.random_conditions = args.Has("random-conditions");

    const sim::Simulator simulator(options);
    const std::string out_dir = args.positional().front();
    std::cerr << "simulate: " << simulator.profile().Describe() << ", seed " << options.seed
              << (options.hard ? ", hard" : "") << (options.noise ? "" : ", no noise") << "\n";
    if (const sim::SceneConditions* c = simulator.conditions()) {
      const sim::OriginVisibility& v = simulator.origin_visibility();
      std::cerr << StringPrintf(
          "simulate: conditions: origin %s (%s), %s views: seen in %d of %d room frames, %.0f px, "
          "%.0f deg; %zu room markers of %.2f m; response %s%s; depth scale %+.3f %%, field %.1f "
          "mm%s; breathing %.1f mm; depth %+.1f ms after its colour\n",
          c->origin_placement.c_str(), c->origin_surface.c_str(), c->origin_visibility.c_str(),
          v.visible_frames, v.frames, v.median_side_px, v.median_angle_deg,
          simulator.world().room_markers.size() - 1, c->room_marker_size_m,
          sim::ResponseName(c->response).c_str(), c->auto_exposure ? " + auto exposure" : "",
          100 * c->depth_scale_error, c->depth_field_mm, c->flying_pixels ? ", flying pixels" : "",
          c->breathing_mm, c->depth_delay_ms);
    }
    int last_percent = -1;
    const sim::SimulationReport report =
        simulator.WriteCase(out_dir, [&](int done, int total) {
          const int percent = 100 * done / total;
          if (percent / 10 != last_percent / 10) {
            std::cerr << "  " << done << "/" << total << " frames\n";
            last_percent = percent;
          }
        });
    std::cout << StringPrintf(
        "wrote %s: %d frames, %.1f MB, %.1f s (%.1f ms/frame: render %.1f, waiting for PNG writes %.1f)\n",
        out_dir.c_str(), report.frames, report.bytes / 1e6, report.seconds,
        1000.0 * report.seconds / std::max(1, report.frames), 1000.0 * report.render_seconds / std::max(1, report.frames),
        1000.0 * report.write_seconds / std::max(1, report.frames));
    return 0;
  } catch (const InputError& e) {
    std::cerr << "simulate: " << e.what() << "\n";
    return 2;
  }
}

}  // namespace arpos
