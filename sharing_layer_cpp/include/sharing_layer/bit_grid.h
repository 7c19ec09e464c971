#ifndef SHARING_LAYER_BIT_GRID_H
#define SHARING_LAYER_BIT_GRID_H

#include <cstddef>
#include <cstdint>
#include <vector>

namespace sharing_layer
{
/**
 * @brief One bit per cell of a grid: what the core keeps per cell beside the costmap, an eighth of a byte each,
 * where a byte per cell would add a costmap's worth of memory per yes/no fact (issue 13: sharing should add
 * little to ObstacleLayer's one byte per cell).
 */
class BitGrid
{
public:
  /// @brief cell_count cells, all false.
  void assign(std::size_t cell_count)
  {
    words_.assign((cell_count + 63) / 64, 0);
    size_ = cell_count;
  }
  /// @brief No cells (and no memory).
  void release()
  {
    std::vector<std::uint64_t>().swap(words_);
    size_ = 0;
  }
  bool empty() const { return size_ == 0; }
  std::size_t size() const { return size_; }
  std::size_t bytes() const { return words_.size() * sizeof(std::uint64_t); }

  bool test(std::size_t index) const { return (words_[index >> 6] >> (index & 63)) & 1u; }
  void set(std::size_t index) { words_[index >> 6] |= std::uint64_t{ 1 } << (index & 63); }
  void reset(std::size_t index) { words_[index >> 6] &= ~(std::uint64_t{ 1 } << (index & 63)); }
  void set(std::size_t index, bool value) { value ? set(index) : reset(index); }

private:
  std::vector<std::uint64_t> words_;
  std::size_t size_ = 0;
};
}  // namespace sharing_layer

#endif  // SHARING_LAYER_BIT_GRID_H
