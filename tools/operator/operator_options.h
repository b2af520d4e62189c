// fovea-operator's command line: its options, --help's text, and the parser
// that checks each value and which options go together.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "core/result.h"
#include "net/wire.h"

namespace fovea::tools {

// --help's text (operator_options.cpp).
extern const char* const kOperatorHelp;

struct OperatorOptions {
  std::string connect;
  std::optional<std::string> key_file;
  bool insecure = false;
  std::string gaze;
  double duration_s = 0.0;
  std::string summary_path;
  std::string frame_log_path;
  std::string ply_dir;
  std::optional<uint32_t> held_frame;  // --save-held ID:FILE
  std::string held_path;
  std::string name = "fovea-operator";
  double budget_mbps = 0.0;
  long mtu = static_cast<long>(net::kDefaultMtu);
  double gaze_hz = 120.0;
  bool quiet = false;
  long max_points = 640 * 480;
  long map_points = 1L << 20;
  long map_bricks = 4096;
  std::string clock = "auto";
  std::string view;  // --view [ADDR:]PORT; empty: no viewer
  std::string record_path;  // --record FILE.mcap
  std::string replay_path;  // --replay FILE.mcap: no robot
  double speed = 1.0;       // --replay's pace (0: as fast as it reads)
  long view_tabs = 4;
  std::string foxglove;  // --foxglove [ADDR:]PORT; empty: no Foxglove server
  long foxglove_clients = 8;
};

// --help or -h anywhere on the command line.
bool wantsHelp(int argc, char** argv);

// kInvalidArgument with the message to print for a bad value or combination.
Result<OperatorOptions> parseOptions(int argc, char** argv);

}  // namespace fovea::tools
