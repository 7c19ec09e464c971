#ifndef SHARING_LAYER_BIT_GRID_H
#define SHARING_LAYER_BIT_GRID_H

#include <cstddef>
#include <cstdint>

#include "sharing_layer/tile_pool.h"

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
    size_ = cell_count;
    tiles_.assign((cell_count + 63) / 64, { 0, ~std::uint64_t{ 0 } });  // constants: kZeros, kOnes
  }
  /// @brief No cells (and no memory).
  void release()
  {
    tiles_.release();
    size_ = 0;
  }
  bool empty() const { return size_ == 0; }
  std::size_t size() const { return size_; }
  /// @return the heap it holds: directory, tiles (with what their vectors reserved) and the free list
  std::size_t bytes() const { return tiles_.bytes(); }
  /// @return tiles neither all false nor all true (each takes kTileCells / 8 bytes)
  std::size_t mixedTiles() const { return tiles_.tilesInUse(); }

  bool test(std::size_t index) const { return (tiles_.at(index / 64) >> (index & 63)) & 1u; }
  void set(std::size_t index) { put<true>(index); }
  void reset(std::size_t index) { put<false>(index); }
  void set(std::size_t index, bool value) { value ? set(index) : reset(index); }

private:
  static constexpr std::size_t kWords = kTileCells / 64;
  static constexpr std::uint32_t kZeros = 0;  ///< the shared all-false tile
  static constexpr std::uint32_t kOnes = 1;   ///< the shared all-true tile

  /// @brief Sets one cell to kValue: a constant tile of the other value is copied first, and a tile left uniform
  /// points at its constant again.
  template <bool kValue>
  void put(std::size_t index)
  {
    constexpr std::uint32_t kSame = kValue ? kOnes : kZeros, kOther = kValue ? kZeros : kOnes;
    constexpr std::uint64_t kUniform = kValue ? ~std::uint64_t{ 0 } : 0;
    std::uint32_t& tile = tiles_.slot(index / 64);
    if (tile == kSame)
    {
      return;
    }
    if (tile == kOther)
    {
      tile = tiles_.newTile(~kUniform);
    }
    std::uint64_t& w = tiles_.inTile(tile, index / 64);
    const std::uint64_t bit = std::uint64_t{ 1 } << (index & 63);
    w = kValue ? (w | bit) : (w & ~bit);
    if (w == kUniform)
    {
      settle(tile);
    }
  }
  /// @brief Points a tile (at `slot` in the directory) at a constant once its cells are all false or all true.
  void settle(std::uint32_t& slot)
  {
    const std::uint64_t* w = tiles_.tileData(slot);
    bool zeros = true, ones = true;
    for (std::size_t i = 0; i < kWords; ++i)
    {
      zeros = zeros && w[i] == 0;
      ones = ones && w[i] == ~std::uint64_t{ 0 };
    }
    if (zeros || ones)
    {
      tiles_.giveBack(slot, zeros ? kZeros : kOnes);
    }
  }

  TilePool<std::uint64_t, kWords, 2> tiles_;  ///< words of 64 cells, kWords to a tile
  std::size_t size_ = 0;
};
}  // namespace sharing_layer

#endif  // SHARING_LAYER_BIT_GRID_H
