#ifndef SHARING_LAYER_FAN_CLEARING_H
#define SHARING_LAYER_FAN_CLEARING_H

#include <cstddef>
#include <cstdint>
#include <vector>

#include "sharing_layer/raytrace.h"

namespace sharing_layer
{
/// What one clearFan did, for tests and benchmarks: how much of the fan went through the near-field fill.
struct FanStats
{
  std::size_t groups = 0;             ///< runs of neighbouring beams filled together near the start
  std::size_t grouped_beams = 0;      ///< beams in those runs (the rest were raytraced from their start)
  std::size_t near_cells = 0;         ///< cells the fill wrote, against grouped_beams * (kNearSteps + 1) steps
};

/**
 * @brief Writes value into every cell raytraceLine visits on each line, all lines starting at cell (x0, y0) of a
 * grid size_x cells wide: a scan's clearing, the same cells as raytracing beam by beam (the order differs, which
 * clearing does not see: every write is the same value).
 *
 * Near the sensor the beams of a scan overlap: in the 30 m reference scan the first 100 steps of all beams are
 * 98,000 Bresenham steps over 25,000 cells, and at raytrace_range 3 m a scan's 60,000 steps cover 8,500 cells.
 * Beams next to each other in the same octant, whose exact lines stay within one cell of each other along b over
 * the first S steps, cover at each step up to S a run of cells without a gap, from the lowest beam's cell to the
 * highest's: that run is written once (the near-field fill), and each beam is raytraced on from step S + 1. S is
 * kNearSteps, or the run's shortest beam's last step where that comes first; a beam too short to join a run (it
 * would cut the run's S to less than half) is raytraced alone.
 *
 * Why the fill is exact, for beams of one octant (same dominant axis a and signs), at step s along a:
 * - beam k's b (its carries) is floor((h_k + s B_k) / A_k), with A = |da|, B = |db| and h = floor(A / 2), the
 *   error term bresenham2D starts with;
 * - b only grows with the slope B / A. Were b_k < z <= b_n for some integer z while B_k / A_k >= B_n / A_n, then
 *   s B_k / A_k <= z - (h_k + 1) / A_k and s B_n / A_n >= z - h_n / A_n, so 0 <= s (B_k / A_k - B_n / A_n) <=
 *   h_n / A_n - (h_k + 1) / A_k, which is below 0 as h_n / A_n <= 1/2 < (h_k + 1) / A_k: impossible. So the
 *   least and the greatest b at each step are those of the run's flattest and steepest beams;
 * - neighbours in a run satisfy S' |B_j / A_j - B_k / A_k| + 1 / (2 min(A_j, A_k)) < 1, S' the lesser of their own
 *   near steps, at least S (h / A lies in [1/2 - 1/(2A), 1/2]), so their b differ by at most one at every step up
 *   to S: taken in scan order, the run's b move by at most one from beam to beam, and cover every value between
 *   the least and the greatest.
 */
FanStats clearFan(std::uint8_t* costs, unsigned int size_x, unsigned int x0, unsigned int y0,
                  const std::vector<LineSteps>& lines, std::uint8_t value);

/// Steps from the start that the near-field fill covers at most (fewer where a run's beams end sooner).
constexpr unsigned int kNearSteps = 64;

}  // namespace sharing_layer

#endif  // SHARING_LAYER_FAN_CLEARING_H
