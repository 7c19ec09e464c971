#ifndef SHARING_LAYER_SCAN_UPDATE_H
#define SHARING_LAYER_SCAN_UPDATE_H

#include <vector>

#include "sharing_layer/cell_flags.h"
#include "sharing_layer/cost_grid.h"
#include "sharing_layer/observation.h"

namespace sharing_layer
{
/**
 * @brief Which cells a scan should report when it clears them: the present cells of the monitored
 * obstacles, since only a present cell can be cleared from an obstacle.
 *
 * Raytracing is left exactly as without a watch. The scan flags the watched cells in CellFlags, and
 * walks again only the beams pointing at a region, over the steps inside it: monitoring costs a pass over the
 * watched cells and a walk over the watched area in view, nothing per cell outside it.
 */
struct ScanWatch
{
  std::vector<std::uint32_t> cells;  ///< watched cell indexes (duplicates allowed)
  /// A watched cell counts as seen free (ScanTouch::watched_free) only when a beam passes through it and
  /// its endpoint lies at least this far (m) beyond the cell. Cleared cells closer to the endpoint are
  /// reported in watched_cleared only: they may be the face the beam hit, or a neighbour it grazed.
  double free_margin = 0.0;
  /// Shadow filter: the endpoint distance used for free_margin is the shortest among a beam and this many
  /// neighbouring points on each side (observation order = scan order), so beams at an occlusion edge,
  /// which localisation error moves through the cells hidden behind a corner, see nothing free there.
  unsigned int free_neighbours = 0;
  /// Optional: rectangles that together cover every listed cell (e.g. the obstacles' rectangles). Beams
  /// are tested against these instead of against each cell, which is cheaper when they hold many cells.
  /// Required for cells flagged in the scratch (see scratch): only those inside a region are watched.
  std::vector<CellRect> regions;
  /// Watched as cells, but covered by no region (scattered cells): walked one by one, and only when this scan
  /// did not mark them again.
  std::vector<std::uint32_t> loose_cells;
  /// Optional: per-cell flags of the grid's size, which the scan leaves as it found them. Without them a watching
  /// scan uses flags of its own per call. A cell may hold kFlaggedWatched: it is then watched without being listed,
  /// when it lies in one of the regions (an owner that keeps its watched cells flagged between scans does not list
  /// them in every scan). kOwnerBits are the owner's: the scan neither reads nor changes them. The scan's own bits
  /// (CellFlags::kScanBits) must be clear.
  CellFlags* scratch = nullptr;
  static constexpr std::uint8_t kFlaggedWatched = CellFlags::kFlaggedWatched;
  /// Optional: the cell of each observation point, as GridGeometry::worldToMap gives it (x kNoCell where it fails or
  /// where the point is not used), for a caller that looked them up already: the scan does not look them up again.
  /// Empty, or one per point.
  struct Cell
  {
    unsigned int x, y;
  };
  std::vector<Cell> point_cells;
  static constexpr unsigned int kNoCell = 0xFFFFFFFFu;
  static constexpr std::uint8_t kOwnerBits = CellFlags::kOwnerBits;

  /// @brief A watch over every cell of the given rectangles (clipped to the grid).
  static ScanWatch fromRects(const GridGeometry& geometry, const std::vector<CellRect>& rects);

  /// @return whether nothing is watched: no cell listed, and no region for flagged cells
  bool empty() const { return cells.empty() && loose_cells.empty() && (regions.empty() || scratch == nullptr); }
};

/**
 * @brief Clears and then marks one observation in a grid, with costmap_2d ObstacleLayer's rules.
 *
 * Clearing (raytraceFreespace): skipped entirely when the origin is off the grid; each
 * endpoint is first clipped to the grid edge, then the Bresenham line from the origin is
 * set to FREE_SPACE for at most raytrace_range (the endpoint cell included).
 * Marking: endpoints closer than obstacle_range (3D distance to the origin) and inside the
 * grid are set to LETHAL_OBSTACLE. Points outside the height limits or not finite are ignored
 * for both.
 *
 * The watched cells this scan cleared and did not mark again are returned in watched_cleared, so a
 * caller can tell which known cells this scan saw free; those among them that a beam passed with its
 * endpoint at least watch.free_margin beyond, and that hold no endpoint of this scan, are also returned in
 * watched_free (evidence of free space). Watched cells holding an endpoint at any range (usable points
 * only) are returned in watched_hit (evidence of occupancy, also beyond obstacle_range).
 * The grid ends exactly as without a watch. Watched cell indexes must lie in the grid.
 *
 * @throws std::invalid_argument when the limits are invalid (grid left untouched)
 */
ScanTouch applyScan(CostGrid& grid, const Observation& observation, const ScanLimits& limits,
                    const ScanWatch& watch = ScanWatch());

}  // namespace sharing_layer

#endif  // SHARING_LAYER_SCAN_UPDATE_H
