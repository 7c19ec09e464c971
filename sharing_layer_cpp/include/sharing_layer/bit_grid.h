#ifndef SHARING_LAYER_BIT_GRID_H
#define SHARING_LAYER_BIT_GRID_H

#include <cstddef>
#include <cstdint>
#include <vector>

namespace sharing_layer
{
/**
 * @brief One bit per cell of a grid, stored in tiles of kTileCells consecutive cells of which only the mixed ones take
 * memory: a tile whose cells are all false or all true is a shared constant. What the core keeps per cell beside
 * the costmap is mostly sparse (shared obstacles' rectangles, fleet robots' footprints) or made of large uniform
 * areas (the a-priori map's unknown outside, its free inside), so a grid costs its directory (4 bytes per tile, 1/128
 * byte per cell) plus 64 bytes per mixed tile, not an eighth of a byte per cell (issues 13 and 29).
 */
class BitGrid
{
public:
  static constexpr std::size_t kTileCells = 512;  ///< cells per tile (8 words of 64 bits)

  /// @brief cell_count cells, all false.
  void assign(std::size_t cell_count)
  {
    release();
    size_ = cell_count;
    dir_.assign((cell_count + kTileCells - 1) / kTileCells, kZeros);
    pool_.assign(2 * kWords, 0);
    for (std::size_t w = kWords; w < 2 * kWords; ++w)
    {
      pool_[w] = ~std::uint64_t{ 0 };
    }
  }
  /// @brief No cells (and no memory).
  void release()
  {
    std::vector<std::uint32_t>().swap(dir_);
    std::vector<std::uint64_t>().swap(pool_);
    std::vector<std::uint32_t>().swap(free_);
    size_ = 0;
  }
  bool empty() const { return size_ == 0; }
  std::size_t size() const { return size_; }
  /// @return the heap it holds: directory, tiles (with what their vectors reserved) and the free list
  std::size_t bytes() const
  {
    return dir_.capacity() * sizeof(std::uint32_t) + pool_.capacity() * sizeof(std::uint64_t) +
           free_.capacity() * sizeof(std::uint32_t);
  }
  /// @return the tiles that take memory (neither all false nor all true)
  std::size_t mixedTiles() const { return pool_.empty() ? 0 : pool_.size() / kWords - 2 - free_.size(); }

  bool test(std::size_t index) const { return (word(index) >> (index & 63)) & 1u; }
  void set(std::size_t index)
  {
    std::uint32_t& tile = dir_[index / kTileCells];
    if (tile == kOnes)
    {
      return;
    }
    if (tile == kZeros)
    {
      tile = newTile(kZeros);
    }
    std::uint64_t& w = pool_[tile * kWords + (index % kTileCells) / 64];
    w |= std::uint64_t{ 1 } << (index & 63);
    if (w == ~std::uint64_t{ 0 })
    {
      settle(tile);
    }
  }
  void reset(std::size_t index)
  {
    std::uint32_t& tile = dir_[index / kTileCells];
    if (tile == kZeros)
    {
      return;
    }
    if (tile == kOnes)
    {
      tile = newTile(kOnes);
    }
    std::uint64_t& w = pool_[tile * kWords + (index % kTileCells) / 64];
    w &= ~(std::uint64_t{ 1 } << (index & 63));
    if (w == 0)
    {
      settle(tile);
    }
  }
  void set(std::size_t index, bool value) { value ? set(index) : reset(index); }

private:
  static constexpr std::size_t kWords = kTileCells / 64;
  static constexpr std::uint32_t kZeros = 0;  ///< the shared all-false tile
  static constexpr std::uint32_t kOnes = 1;   ///< the shared all-true tile

  std::uint64_t word(std::size_t index) const
  {
    return pool_[dir_[index / kTileCells] * kWords + (index % kTileCells) / 64];
  }
  /// @return a tile of its own holding what `like` (kZeros or kOnes) holds
  std::uint32_t newTile(std::uint32_t like)
  {
    std::uint32_t tile = 0;
    if (!free_.empty())
    {
      tile = free_.back();
      free_.pop_back();
    }
    else
    {
      tile = static_cast<std::uint32_t>(pool_.size() / kWords);
      pool_.resize(pool_.size() + kWords);
    }
    const std::uint64_t fill = like == kOnes ? ~std::uint64_t{ 0 } : 0;
    for (std::size_t w = 0; w < kWords; ++w)
    {
      pool_[tile * kWords + w] = fill;
    }
    return tile;
  }
  /// @brief A tile (at `slot` in the directory) that may have become uniform goes back to the shared constant.
  void settle(std::uint32_t& slot)
  {
    const std::uint64_t* w = &pool_[slot * kWords];
    bool zeros = true, ones = true;
    for (std::size_t i = 0; i < kWords; ++i)
    {
      zeros = zeros && w[i] == 0;
      ones = ones && w[i] == ~std::uint64_t{ 0 };
    }
    if (zeros || ones)
    {
      free_.push_back(slot);
      slot = zeros ? kZeros : kOnes;
    }
  }

  std::vector<std::uint32_t> dir_;   ///< per tile: its place in pool_ (kZeros, kOnes: the shared constants)
  std::vector<std::uint64_t> pool_;  ///< the tiles, kWords words each; the first two are the constants
  std::vector<std::uint32_t> free_;  ///< tiles of pool_ no longer used
  std::size_t size_ = 0;
};
}  // namespace sharing_layer

#endif  // SHARING_LAYER_BIT_GRID_H
