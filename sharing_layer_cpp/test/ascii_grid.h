// Test helper: draws cell sets as ASCII maps so golden cases read like pictures.
#ifndef SHARING_LAYER_TEST_ASCII_GRID_H
#define SHARING_LAYER_TEST_ASCII_GRID_H

#include <cstdint>
#include <string>
#include <vector>

namespace sharing_layer
{
namespace test
{
/// Rows from the top line (y = size_y - 1) down to y = 0, so the picture has y pointing up.
/// '#' = a cell in the set, '.' = not.
inline std::string drawCells(const std::vector<std::uint32_t>& cells, unsigned int size_x, unsigned int size_y)
{
  std::string grid(size_x * size_y, '.');
  for (std::uint32_t index : cells)
  {
    grid[index] = '#';
  }
  std::string out;
  for (int y = static_cast<int>(size_y) - 1; y >= 0; --y)
  {
    out += grid.substr(static_cast<std::size_t>(y) * size_x, size_x) + "\n";
  }
  return out;
}

/// Joins picture lines with newlines (each line is one row, top row first).
inline std::string picture(const std::vector<std::string>& rows)
{
  std::string out;
  for (const auto& row : rows)
  {
    out += row + "\n";
  }
  return out;
}
}  // namespace test
}  // namespace sharing_layer

#endif  // SHARING_LAYER_TEST_ASCII_GRID_H
