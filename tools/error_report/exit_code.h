// fovea-error-report's exit codes: main returns them, and so does each step that
// can end a run (measuring, writing), having said why on standard error.
#pragma once

namespace fovea::tools {

inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;  // a flag, camera or configuration that cannot be used

}  // namespace fovea::tools
