#ifndef SHARING_LAYER_RAYTRACE_H
#define SHARING_LAYER_RAYTRACE_H

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdlib>

namespace sharing_layer
{
/// @return -1, 0 or 1 (costmap_2d's sign() returns -1 for 0; ours does not, and nothing here depends on it)
inline int signOf(int x)
{
  return (x > 0) - (x < 0);
}

/**
 * @brief Walks a Bresenham line on flat offsets, as costmap_2d's Costmap2D::bresenham2D.
 *
 * Steps along the dominant axis "a"; the action is applied to min(max_length, abs_da)
 * cells and then once more to the cell reached, so the endpoint is included when the
 * line is not cut short by max_length.
 */
template <class Action>
inline void bresenham2D(Action& at, unsigned int abs_da, unsigned int abs_db, int error_b, int offset_a,
                        int offset_b, std::uint32_t offset, unsigned int max_length)
{
  const unsigned int end = std::min(max_length, abs_da);
  for (unsigned int i = 0; i < end; ++i)
  {
    at(offset);
    offset += offset_a;
    error_b += abs_db;
    if (static_cast<unsigned int>(error_b) >= abs_da)
    {
      offset += offset_b;
      error_b -= abs_da;
    }
  }
  at(offset);
}

/**
 * @brief Applies an action to every cell on the line from (x0, y0) to (x1, y1), as
 * costmap_2d's Costmap2D::raytraceLine: the line is cut to max_length cells
 * (Euclidean, measured in cells) and the cells are visited from the start outwards.
 * Both ends must lie inside a grid of width size_x.
 */
template <class Action>
inline void raytraceLine(Action& at, unsigned int x0, unsigned int y0, unsigned int x1, unsigned int y1,
                         unsigned int size_x, unsigned int max_length = UINT_MAX)
{
  const int dx = static_cast<int>(x1) - static_cast<int>(x0);
  const int dy = static_cast<int>(y1) - static_cast<int>(y0);
  const unsigned int abs_dx = static_cast<unsigned int>(std::abs(dx));
  const unsigned int abs_dy = static_cast<unsigned int>(std::abs(dy));
  const int offset_dx = signOf(dx);
  const int offset_dy = signOf(dy) * static_cast<int>(size_x);
  const std::uint32_t offset = y0 * size_x + x0;

  const double dist = std::hypot(static_cast<double>(dx), static_cast<double>(dy));
  const double scale = (dist == 0.0) ? 1.0 : std::min(1.0, max_length / dist);

  if (abs_dx >= abs_dy)
  {
    const int error_y = static_cast<int>(abs_dx / 2);
    bresenham2D(at, abs_dx, abs_dy, error_y, offset_dx, offset_dy, offset,
                static_cast<unsigned int>(scale * abs_dx));
    return;
  }
  const int error_x = static_cast<int>(abs_dy / 2);
  bresenham2D(at, abs_dy, abs_dx, error_x, offset_dy, offset_dx, offset, static_cast<unsigned int>(scale * abs_dy));
}

/**
 * @brief bresenham2D with two actions: the first deep_steps cells (steps 0 .. deep_steps - 1 along the
 * dominant axis) get deep, the rest shallow. The cells visited are exactly those of bresenham2D.
 */
template <class DeepAction, class ShallowAction>
inline void bresenham2DSplit(DeepAction& deep, ShallowAction& shallow, unsigned int abs_da, unsigned int abs_db,
                             int error_b, int offset_a, int offset_b, std::uint32_t offset, unsigned int max_length,
                             unsigned int deep_steps)
{
  const unsigned int end = std::min(max_length, abs_da);
  const unsigned int split = std::min(end, deep_steps);
  unsigned int i = 0;
  for (; i < split; ++i)
  {
    deep(offset);
    offset += offset_a;
    error_b += abs_db;
    if (static_cast<unsigned int>(error_b) >= abs_da)
    {
      offset += offset_b;
      error_b -= abs_da;
    }
  }
  for (; i < end; ++i)
  {
    shallow(offset);
    offset += offset_a;
    error_b += abs_db;
    if (static_cast<unsigned int>(error_b) >= abs_da)
    {
      offset += offset_b;
      error_b -= abs_da;
    }
  }
  if (end < deep_steps)
  {
    deep(offset);
  }
  else
  {
    shallow(offset);
  }
}

/**
 * @brief raytraceLine whose cells up to deep_until cells (Euclidean distance from the start cell's centre,
 * in cells) get deep and the cells after that get shallow. Visits the same cells as raytraceLine.
 * A negative deep_until makes every cell shallow.
 */
template <class DeepAction, class ShallowAction>
inline void raytraceLineSplit(DeepAction& deep, ShallowAction& shallow, unsigned int x0, unsigned int y0,
                              unsigned int x1, unsigned int y1, unsigned int size_x, unsigned int max_length,
                              double deep_until)
{
  const int dx = static_cast<int>(x1) - static_cast<int>(x0);
  const int dy = static_cast<int>(y1) - static_cast<int>(y0);
  const unsigned int abs_dx = static_cast<unsigned int>(std::abs(dx));
  const unsigned int abs_dy = static_cast<unsigned int>(std::abs(dy));
  const int offset_dx = signOf(dx);
  const int offset_dy = signOf(dy) * static_cast<int>(size_x);
  const std::uint32_t offset = y0 * size_x + x0;

  const double dist = std::hypot(static_cast<double>(dx), static_cast<double>(dy));
  const double scale = (dist == 0.0) ? 1.0 : std::min(1.0, max_length / dist);
  const unsigned int abs_da = std::max(abs_dx, abs_dy);
  // Step i along the dominant axis lies i * dist / abs_da cells from the start.
  unsigned int deep_steps = 0;
  if (deep_until >= 0.0)
  {
    // (1e-9: a cell exactly deep_until away is deep despite rounding in the caller's arithmetic)
    const double steps = dist == 0.0 ? 1.0 : std::floor(deep_until * abs_da / dist + 1e-9) + 1.0;
    deep_steps = steps >= static_cast<double>(UINT_MAX) ? UINT_MAX : static_cast<unsigned int>(steps);
  }

  if (abs_dx >= abs_dy)
  {
    const int error_y = static_cast<int>(abs_dx / 2);
    bresenham2DSplit(deep, shallow, abs_dx, abs_dy, error_y, offset_dx, offset_dy, offset,
                     static_cast<unsigned int>(scale * abs_dx), deep_steps);
    return;
  }
  const int error_x = static_cast<int>(abs_dy / 2);
  bresenham2DSplit(deep, shallow, abs_dy, abs_dx, error_x, offset_dy, offset_dx, offset,
                   static_cast<unsigned int>(scale * abs_dy), deep_steps);
}

/// @brief Action that replaces every visited cell's value through a 256-entry table.
struct TableAction
{
  std::uint8_t* costs;
  const std::uint8_t* table;
  inline void operator()(std::uint32_t offset) { costs[offset] = table[costs[offset]]; }
};

/// @brief Action that writes one value into every visited cell (costmap_2d's MarkCell).
struct SetCellAction
{
  std::uint8_t* costs;
  std::uint8_t value;
  inline void operator()(std::uint32_t offset) { costs[offset] = value; }
};

/// @brief Action that writes a value and records which cells it visited.
template <class Container>
struct SetAndCollectAction
{
  std::uint8_t* costs;
  std::uint8_t value;
  Container* visited;
  inline void operator()(std::uint32_t offset)
  {
    costs[offset] = value;
    visited->push_back(offset);
  }
};

/// @brief Action that only records the visited cells.
template <class Container>
struct CollectAction
{
  Container* visited;
  inline void operator()(std::uint32_t offset) { visited->push_back(offset); }
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_RAYTRACE_H
