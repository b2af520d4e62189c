#include "pipeline/map/view_judge.h"

namespace fovea::pipeline::map {

void judgeRowRef(const ViewJudgeParams& p, int v, uint8_t* out) {
  const uint16_t* row = p.depth + static_cast<std::size_t>(v) * static_cast<std::size_t>(p.width);
  for (int u = 0; u < p.width; ++u) {
    const uint32_t raw = row[u];
    if (raw == 0 || !p.rule.valid(raw)) {
      out[u] = kJudgedInvalid;
      continue;
    }
    const Eigen::Vector3f q = p.into.apply(p.rule.point(u, v, raw));
    out[u] = p.view.explains(q.x(), q.y(), q.z()) ? kJudgedExplained : kJudgedUnexplained;
  }
}

}  // namespace fovea::pipeline::map
