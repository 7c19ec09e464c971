#ifndef SHARING_LAYER_RAYTRACE_H
#define SHARING_LAYER_RAYTRACE_H

#include <algorithm>
#include <climits>
#include <cstddef>
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
 *
 * The action is taken by value, as costmap_2d takes it, and keeps its state behind pointers. The cell offset is
 * walked in 64 bits: a 32-bit offset is zero-extended again before every write (a quarter more instructions per
 * cell than costmap_2d's loop at -O2); an offset inside the grid is the same number either way. Two steps per pass
 * of the loop: its count and branch once per two cells took the scan pass from 0.87 to 0.80 x upstream's at 3 m
 * (-O2; 0.82 to 0.73 at -O3), the cells visited and their order unchanged (issue 29).
 */
template <class Action>
inline void bresenham2D(Action at, unsigned int abs_da, unsigned int abs_db, int error_b, int offset_a,
                        int offset_b, std::uint32_t offset, unsigned int max_length)
{
  const unsigned int end = std::min(max_length, abs_da);
  std::size_t cell = offset;
  // (a negative step, sign-extended, wraps to the right cell: unsigned arithmetic is modulo 2^64)
  const std::size_t step_a = static_cast<std::size_t>(static_cast<std::ptrdiff_t>(offset_a));
  const std::size_t step_b = static_cast<std::size_t>(static_cast<std::ptrdiff_t>(offset_b));
  const auto step = [&]() {
    at(cell);
    cell += step_a;
    error_b += abs_db;
    if (static_cast<unsigned int>(error_b) >= abs_da)
    {
      cell += step_b;
      error_b -= abs_da;
    }
  };
  unsigned int left = end;
  for (; left >= 2; left -= 2)
  {
    step();
    step();
  }
  if (left != 0)
  {
    step();
  }
  at(cell);
}

/**
 * @brief The Bresenham line of raytraceLine from (x0, y0) to (x1, y1) as steps along its dominant axis "a"
 * (x when |dx| >= |dy|): step i visits a0 + sign_a * i and b0 + sign_b * carries(i), for i = 0 .. end.
 */
struct LineSteps
{
  bool x_major;
  unsigned int abs_da, abs_db;
  int sign_a, sign_b;
  unsigned int end;  ///< the last step visited: abs_da, or fewer when max_length cuts the line

  LineSteps() = default;
  /// The line from (x0, y0) to (x1, y1), cut to max_length cells as raytraceLine cuts it. A constructor, so that a
  /// vector's emplace_back writes the fields in place: built in a temporary by single fields and then copied as one
  /// 16-byte load, each line stalled on store forwarding (the clearing pass's costliest line at -O2; issue 29).
  LineSteps(unsigned int x0, unsigned int y0, unsigned int x1, unsigned int y1, unsigned int max_length = UINT_MAX)
  {
    const int dx = static_cast<int>(x1) - static_cast<int>(x0);
    const int dy = static_cast<int>(y1) - static_cast<int>(y0);
    const unsigned int abs_dx = static_cast<unsigned int>(std::abs(dx));
    const unsigned int abs_dy = static_cast<unsigned int>(std::abs(dy));
    x_major = abs_dx >= abs_dy;
    abs_da = x_major ? abs_dx : abs_dy;
    abs_db = x_major ? abs_dy : abs_dx;
    sign_a = signOf(x_major ? dx : dy);
    sign_b = signOf(x_major ? dy : dx);
    const double dist_sq = static_cast<double>(dx) * dx + static_cast<double>(dy) * dy;
    if (dist_sq <= static_cast<double>(max_length) * max_length)
    {
      end = abs_da;  // scale 1 below: no division for a line within max_length
    }
    else
    {
      const double scale = std::min(1.0, max_length / dist());  // (dist > 0 here: dist_sq > max_length^2 >= 0)
      end = std::min(static_cast<unsigned int>(scale * abs_da), abs_da);
    }
  }

  /// @return cells from the start cell's centre to the end cell's centre (sqrt of the sum of squares rather than
  /// hypot: exact for these integer offsets, at a fraction of the cost; computed when asked, as clearing does not)
  double dist() const
  {
    return std::sqrt(static_cast<double>(abs_da) * abs_da + static_cast<double>(abs_db) * abs_db);
  }

  /// @return how many times the line has moved along b after i steps (bresenham2D's error term, closed form)
  unsigned int carries(unsigned int i) const
  {
    if (abs_da == 0)
    {
      return 0u;
    }
    const std::uint64_t numerator = static_cast<std::uint64_t>(abs_da / 2) + static_cast<std::uint64_t>(i) * abs_db;
    // (a 32-bit division where it fits, as it does on any grid below 65536 cells a side: several times faster)
    return numerator <= UINT32_MAX ? static_cast<std::uint32_t>(numerator) / abs_da
                                   : static_cast<unsigned int>(numerator / abs_da);
  }
};

/**
 * @brief Applies an action to every cell on the line from (x0, y0) to (x1, y1), as
 * costmap_2d's Costmap2D::raytraceLine: the line is cut to max_length cells
 * (Euclidean, measured in cells) and the cells are visited from the start outwards.
 * Both ends must lie inside a grid of width size_x.
 */
template <class Action>
inline void raytraceLine(Action at, unsigned int x0, unsigned int y0, unsigned int x1, unsigned int y1,
                         unsigned int size_x, unsigned int max_length = UINT_MAX)
{
  const LineSteps line(x0, y0, x1, y1, max_length);
  const int row = static_cast<int>(size_x);
  const int offset_a = line.x_major ? line.sign_a : line.sign_a * row;
  const int offset_b = line.x_major ? line.sign_b * row : line.sign_b;
  bresenham2D(at, line.abs_da, line.abs_db, static_cast<int>(line.abs_da / 2), offset_a, offset_b,
              y0 * size_x + x0, line.end);
}

/// @return how many steps along the dominant axis lie within distance (cells) of the start: the steps i with
/// i * dist / abs_da <= distance; 0 for a negative distance
inline unsigned int stepsWithin(double distance, unsigned int abs_da, double dist)
{
  if (distance < 0.0)
  {
    return 0;
  }
  if (dist == 0.0)
  {
    return 1;
  }
  // (1e-9: a cell exactly at the distance counts despite rounding in the caller's arithmetic)
  const double before = distance * abs_da / dist + 1e-9;
  // The conversion truncates, which for this non-negative value is floor (std::floor is a libm call on x86-64's
  // baseline, once per beam the walk reaches).
  return !(before < static_cast<double>(UINT_MAX - 1u)) ? UINT_MAX : static_cast<unsigned int>(before) + 1u;
}

/// @brief Action that writes one value into every visited cell (costmap_2d's MarkCell).
struct SetCellAction
{
  std::uint8_t* costs;
  std::uint8_t value;
  inline void operator()(std::size_t offset) { costs[offset] = value; }
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
