// fovead foveate: the paper's method on a recorded cloud, PLY in, PLY out.
#include <chrono>
#include <cstdio>
#include <string>

#include "firmware/commands.h"
#include "firmware/options.h"
#include "firmware/report.h"
#include "io/ply.h"
#include "pipeline/foveator.h"

namespace fovea::firmware {

namespace {

const char* kFoveateHelp =
    "usage: fovead foveate --in IN.ply --out OUT.ply --gaze-origin X,Y,Z --gaze-dir X,Y,Z\n"
    "                      [--preset F1|F2|F3|FREF|ACUITY] [--m 0.022] [--far-ecc 90] [--fixation centroid|hit|fixed:D0]\n"
    "                      [--ascii]\n"
    "\n"
    "Foveates a recorded point cloud given in world coordinates (PLY, ascii or binary;\n"
    "x y z float or double, optional red green blue) for an eye at --gaze-origin looking\n"
    "along --gaze-dir. Writes x y z (double when the input was double), red green blue\n"
    "when the input had colour, and a vertex property `region` (uchar, 0 = fovea).\n"
    "--fixation centroid is the paper's d0; the default, hit, measures d0 to the first\n"
    "surface along the gaze.\n"
    "\n"
    "  --in FILE, --out FILE    input and output PLY files\n"
    "  --gaze-origin X,Y,Z      eye position, world coordinates in metres\n"
    "  --gaze-dir X,Y,Z         gaze direction (any length > 0)\n"
    "  --ascii                  write ascii PLY (default binary_little_endian)\n";

}  // namespace

int foveateCommand(int argc, char** argv) {
  std::vector<std::string> flags = {"--in", "--out", "--gaze-origin", "--gaze-dir"};
  flags.insert(flags.end(), kFoveationFlags.begin(), kFoveationFlags.end());
  Result<Args> args = Args::parse(argc, argv, 2, flags, {"--help", "-h", "--ascii"});
  auto usage = [](const Status& s) {
    std::fprintf(stderr, "fovead foveate: %s\n", s.message().c_str());
    return kExitUsage;
  };
  if (!args) return usage(args.status());
  if (args->has("--help") || args->has("-h")) {
    std::printf("%s%s", kFoveateHelp, foveationFlagsHelp().c_str());
    return kExitOk;
  }
  for (const char* required : {"--in", "--out", "--gaze-origin", "--gaze-dir"}) {
    if (!args->has(required)) return usage({ErrorCode::kInvalidArgument, std::string(required) + " is required (see --help)"});
  }
  Result<pipeline::FoveationConfig> config = foveationConfigFromArgs(args.value());
  if (!config) return usage(config.status());
  pipeline::Gaze gaze;
  Result<Eigen::Vector3d> origin = parseVector3("--gaze-origin", *args->get("--gaze-origin"));
  if (!origin) return usage(origin.status());
  Result<Eigen::Vector3d> dir = parseVector3("--gaze-dir", *args->get("--gaze-dir"));
  if (!dir) return usage(dir.status());
  gaze.origin_m = origin.value();
  gaze.direction = dir.value();
  if (Result<pipeline::Gaze> unit = pipeline::normalizeGaze(gaze); !unit) {
    return usage({ErrorCode::kInvalidArgument, "--gaze-dir: " + unit.status().message()});
  }

  const std::string& in_path = *args->get("--in");
  Result<io::PlyCloud> input = io::readPly(in_path);
  if (!input) {
    std::fprintf(stderr, "fovead foveate: %s\n", input.status().message().c_str());
    return kExitFailure;
  }
  const pipeline::PointCloud& cloud = input->points;
  const std::size_t capacity = std::max<std::size_t>(cloud.size(), 1);
  Result<pipeline::Foveator> foveator = pipeline::Foveator::create({capacity, capacity}, config.value());
  if (!foveator) return usage(foveator.status());
  pipeline::FoveatedCloud out(capacity);
  pipeline::FoveationStats stats;
  if (Status s = foveator->foveate(cloud, gaze, out, stats); !s) {
    std::fprintf(stderr, "fovead foveate: %s\n", s.message().c_str());
    return kExitFailure;
  }
  io::PlyWriteOptions options;
  options.binary = !args->has("--ascii");
  options.double_coords = input->coords_were_double;
  options.write_color = input->has_color;
  const std::string& out_path = *args->get("--out");
  if (Status s = io::writePly(out_path, out.points, out.region.data(), options); !s) {
    std::fprintf(stderr, "fovead foveate: %s\n", s.message().c_str());
    return kExitFailure;
  }

  std::printf("fovead foveate: %s: %zu points (%zu vertices, %zu with NaN/Inf dropped), %s\n", in_path.c_str(),
              cloud.size(), input->vertex_count_in_file, input->dropped_nonfinite,
              input->coords_were_double ? "double" : "float");
  std::printf("foveation: %s\n", describeFoveation(config.value()).c_str());
  std::printf("d0 %.4f m (%s, from %u points%s)\n", stats.fixation.d0_m,
              std::string(pipeline::fixationSourceName(stats.fixation.source)).c_str(), stats.fixation.support,
              stats.fixation.clamped ? ", clamped to the minimum" : "");
  RegionTotals totals;
  totals.add(stats);
  printRegionTable(stdout, foveator->model(), totals);
  std::printf("time [ms]: partition %.2f, fixation %.2f, sampling %.2f\n", stats.partition_ns * 1e-6,
              stats.fixation_ns * 1e-6, stats.sample_ns * 1e-6);
  std::printf("wrote %zu points to %s\n", out.size(), out_path.c_str());
  return kExitOk;
}

}  // namespace fovea::firmware
