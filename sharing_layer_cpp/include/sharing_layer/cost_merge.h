#ifndef SHARING_LAYER_COST_MERGE_H
#define SHARING_LAYER_COST_MERGE_H

#include <cstddef>
#include <cstdint>

namespace sharing_layer
{
/// @brief A window of cells [min_i, max_i) x [min_j, max_j) of two row-major grids with rows of row_size cells.
struct MergeWindow
{
  std::size_t row_size;
  int min_i, min_j, max_i, max_j;
};

/**
 * @brief costmap_2d's CostmapLayer::updateWithMax: per cell of the window, the layer's cost unless it is
 * NO_INFORMATION (then the master's stays), and the greater one where both are known; a master cell without
 * information takes the layer's.
 *
 * Half a 30 m update cycle is this merge. Upstream's loop reads the layer through a member pointer and branches
 * per cell, so it runs cell by cell; with NO_INFORMATION (255) counted as -1 the whole rule is one unsigned
 * maximum, max(master + 1, layer + 1) - 1 in 8-bit arithmetic, sixteen cells at a time with SSE2 (every x86-64
 * CPU has it; elsewhere cell by cell), whatever the optimisation level.
 * An empty or inverted window merges nothing.
 */
void mergeMax(const std::uint8_t* layer, std::uint8_t* master, const MergeWindow& window);

/// @brief costmap_2d's CostmapLayer::updateWithOverwrite: the layer's cost wherever it is not NO_INFORMATION.
void mergeOverwrite(const std::uint8_t* layer, std::uint8_t* master, const MergeWindow& window);
}  // namespace sharing_layer

#endif  // SHARING_LAYER_COST_MERGE_H
