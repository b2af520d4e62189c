// fovead: the fovea service: run (a camera through the foveation pipeline,
// optionally streamed to an operator), foveate (a recorded PLY cloud) and
// keygen (a pre-shared key for the stream).
#include <cstdio>
#include <cstring>

#include "firmware/commands.h"

namespace {

const char* kHelp =
    "usage: fovead COMMAND [options]\n"
    "\n"
    "Foveated point clouds for immersive telerobotics: full detail where the operator\n"
    "looks, voxel sizes growing with eccentricity as the eye's acuity falls off.\n"
    "\n"
    "commands:\n"
    "  run       run the pipeline on a camera (default: the mock living room) and report;\n"
    "            with --listen, stream it to an operator over UDP\n"
    "  serve     run as a service: stage threads, fixed memory, status lines, systemd\n"
    "            notifications; until SIGTERM (SIGHUP reloads the foveation parameters)\n"
    "  foveate   foveate a recorded PLY cloud for a given gaze and write a PLY\n"
    "  map       fuse posed frames of a camera (a recording, a mock path) into a surfel\n"
    "            map and write it as PLY\n"
    "  keygen    write a new pre-shared key file for the stream\n"
    "  cameras   list the cameras this build can see, with the spec to use for each\n"
    "  print-config  print the effective configuration (board profile, --config FILE,\n"
    "            --set SECTION.KEY=VALUE) as TOML; also 'fovead --print-config'\n"
    "\n"
    "'fovead COMMAND --help' describes each command.\n";

}  // namespace

int main(int argc, char** argv) {
  using namespace fovea::firmware;
  if (argc < 2 || std::strcmp(argv[1], "--help") == 0 || std::strcmp(argv[1], "-h") == 0 ||
      std::strcmp(argv[1], "help") == 0) {
    std::fputs(kHelp, argc < 2 ? stderr : stdout);
    return argc < 2 ? kExitUsage : kExitOk;
  }
  if (std::strcmp(argv[1], "--version") == 0) {
    std::printf("fovead %s\n", FOVEA_VERSION);
    return kExitOk;
  }
  if (std::strcmp(argv[1], "run") == 0) return runCommand(argc, argv);
  if (std::strcmp(argv[1], "serve") == 0) return serveCommand(argc, argv);
  if (std::strcmp(argv[1], "foveate") == 0) return foveateCommand(argc, argv);
  if (std::strcmp(argv[1], "keygen") == 0) return keygenCommand(argc, argv);
  if (std::strcmp(argv[1], "cameras") == 0) return camerasCommand(argc, argv);
  if (std::strcmp(argv[1], "map") == 0) return mapCommand(argc, argv);
  if (std::strcmp(argv[1], "print-config") == 0 || std::strcmp(argv[1], "--print-config") == 0) {
    return printConfigCommand(argc, argv);
  }
  std::fprintf(stderr, "fovead: unknown command '%s' (see fovead --help)\n", argv[1]);
  return kExitUsage;
}
