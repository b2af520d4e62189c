// fovea-operator: the operator station without the headset. Says hello to a
// fovead stream, sends gaze from a script, receives and decodes the foveated
// frames, and measures what an operator would feel: frames per second, bytes on
// the wire, end-to-end latency, losses. The decoding is fovea::net's library
// (ChunkEncoder's counterpart), which a VR front end links the same way.
//
// This file holds main and the stop signal; the command line is
// operator_options.cpp, the set-up operator_station.cpp, and the run over the
// sessions (or a replay) the class in operator_run.h.
#include <csignal>
#include <cstdio>

#include "tools/operator/operator_exit.h"
#include "tools/operator/operator_options.h"
#include "tools/operator/operator_run.h"
#include "tools/operator/operator_station.h"

namespace fovea::tools {

volatile std::sig_atomic_t g_stop = 0;

}  // namespace fovea::tools

namespace {

extern "C" void onStopSignal(int) { fovea::tools::g_stop = 1; }

}  // namespace

int main(int argc, char** argv) {
  using namespace fovea::tools;
  if (wantsHelp(argc, argv)) {
    std::fputs(kOperatorHelp, stdout);
    return kExitOk;
  }
  fovea::Result<OperatorOptions> parsed = parseOptions(argc, argv);
  if (!parsed) {
    std::fprintf(stderr, "fovea-operator: %s\n", parsed.status().message().c_str());
    return kExitUsage;
  }
  const OperatorOptions& opt = parsed.value();
  Station station;
  if (Exit e = setUp(opt, station)) return *e;
  std::signal(SIGINT, onStopSignal);
  std::signal(SIGTERM, onStopSignal);
  OperatorRun run(opt, station);
  if (Exit e = opt.replay_path.empty() ? run.runSessions() : run.runReplay()) return *e;
  const int code = run.finish();
  closeRecording(station);
  return code;
}
