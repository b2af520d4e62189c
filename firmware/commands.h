// fovead's commands; each returns the process exit code.
#pragma once

namespace fovea::firmware {

// Exit codes: 0 success, 2 bad arguments, 1 runtime failure (I/O, device, data).
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;

int runCommand(int argc, char** argv);      // fovead run ...
int foveateCommand(int argc, char** argv);  // fovead foveate ...
int keygenCommand(int argc, char** argv);   // fovead keygen FILE
int printConfigCommand(int argc, char** argv);  // fovead print-config ... (also --print-config)
int serveCommand(int argc, char** argv);    // fovead serve ...
int camerasCommand(int argc, char** argv);  // fovead cameras
int mapCommand(int argc, char** argv);      // fovead map ...

}  // namespace fovea::firmware
