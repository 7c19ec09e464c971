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
 * @brief bresenham2D with three actions by step along the dominant axis: plain before start_steps, deep from
 * there before deep_steps, shallow from there before watch_steps, plain again after. The cells visited are
 * exactly those of bresenham2D.
 */
template <class DeepAction, class ShallowAction, class PlainAction>
inline void bresenham2DSplit(DeepAction& deep, ShallowAction& shallow, PlainAction& plain, unsigned int abs_da,
                             unsigned int abs_db, int error_b, int offset_a, int offset_b, std::uint32_t offset,
                             unsigned int max_length, unsigned int start_steps, unsigned int deep_steps,
                             unsigned int watch_steps)
{
  const unsigned int end = std::min(max_length, abs_da);
  const unsigned int s0 = std::min(end, start_steps);
  const unsigned int s1 = std::min(end, std::max(s0, deep_steps));
  const unsigned int s2 = std::min(end, std::max(s1, watch_steps));
  unsigned int i = 0;
#define SHARING_LAYER_BRESENHAM_STEP(action)                                                                          \
  action(offset);                                                                                                    \
  offset += offset_a;                                                                                                \
  error_b += abs_db;                                                                                                 \
  if (static_cast<unsigned int>(error_b) >= abs_da)                                                                  \
  {                                                                                                                  \
    offset += offset_b;                                                                                              \
    error_b -= abs_da;                                                                                               \
  }
  for (; i < s0; ++i)
  {
    SHARING_LAYER_BRESENHAM_STEP(plain)
  }
  for (; i < s1; ++i)
  {
    SHARING_LAYER_BRESENHAM_STEP(deep)
  }
  for (; i < s2; ++i)
  {
    SHARING_LAYER_BRESENHAM_STEP(shallow)
  }
  for (; i < end; ++i)
  {
    SHARING_LAYER_BRESENHAM_STEP(plain)
  }
#undef SHARING_LAYER_BRESENHAM_STEP
  if (end < start_steps || end >= watch_steps)
  {
    plain(offset);
  }
  else if (end < deep_steps)
  {
    deep(offset);
  }
  else
  {
    shallow(offset);
  }
}

/// @return how many steps along the dominant axis lie within distance (cells) of the start: the steps i with
/// i * dist / abs_da <= distance; 0 for a negative distance
inline unsigned int stepsWithin(double distance, unsigned int abs_da, double dist)
{
  if (distance < 0.0)
  {
    return 0;
  }
  // (1e-9: a cell exactly at the distance counts despite rounding in the caller's arithmetic)
  const double steps = dist == 0.0 ? 1.0 : std::floor(distance * abs_da / dist + 1e-9) + 1.0;
  return steps >= static_cast<double>(UINT_MAX) ? UINT_MAX : static_cast<unsigned int>(steps);
}

/**
 * @brief raytraceLine with three actions by distance from the start cell's centre (in cells): plain before
 * watch_from, deep up to deep_until, shallow up to watch_until, plain beyond. Visits the same cells as
 * raytraceLine. Only cells between watch_from and watch_until may hold flags the deep and shallow actions
 * read; a negative deep_until makes no cell deep.
 */
template <class DeepAction, class ShallowAction, class PlainAction>
inline void raytraceLineSplit(DeepAction& deep, ShallowAction& shallow, PlainAction& plain, unsigned int x0,
                              unsigned int y0, unsigned int x1, unsigned int y1, unsigned int size_x,
                              unsigned int max_length, double watch_from, double deep_until, double watch_until)
{
  const int dx = static_cast<int>(x1) - static_cast<int>(x0);
  const int dy = static_cast<int>(y1) - static_cast<int>(y0);
  const unsigned int abs_dx = static_cast<unsigned int>(std::abs(dx));
  const unsigned int abs_dy = static_cast<unsigned int>(std::abs(dy));
  const int offset_dx = signOf(dx);
  const int offset_dy = signOf(dy) * static_cast<int>(size_x);
  const std::uint32_t offset = y0 * size_x + x0;

  const double dist = std::sqrt(static_cast<double>(dx) * dx + static_cast<double>(dy) * dy);
  const double scale = (dist == 0.0) ? 1.0 : std::min(1.0, max_length / dist);
  const unsigned int abs_da = std::max(abs_dx, abs_dy);
  // Steps strictly before watch_from are plain: stepsWithin of a hair less.
  const unsigned int start_steps = watch_from <= 0.0 ? 0 : stepsWithin(watch_from - 1e-6, abs_da, dist);
  const unsigned int watch_steps = stepsWithin(watch_until, abs_da, dist);
  const unsigned int deep_steps = std::min(watch_steps, stepsWithin(deep_until, abs_da, dist));

  if (abs_dx >= abs_dy)
  {
    const int error_y = static_cast<int>(abs_dx / 2);
    bresenham2DSplit(deep, shallow, plain, abs_dx, abs_dy, error_y, offset_dx, offset_dy, offset,
                     static_cast<unsigned int>(scale * abs_dx), start_steps, deep_steps, watch_steps);
    return;
  }
  const int error_x = static_cast<int>(abs_dy / 2);
  bresenham2DSplit(deep, shallow, plain, abs_dy, abs_dx, error_x, offset_dy, offset_dx, offset,
                   static_cast<unsigned int>(scale * abs_dy), start_steps, deep_steps, watch_steps);
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
