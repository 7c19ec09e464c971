#ifndef SHARING_LAYER_TILE_POOL_H
#define SHARING_LAYER_TILE_POOL_H

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace sharing_layer
{
/**
 * @brief The storage behind BitGrid and CellFlags: a grid's cells in tiles of kPerTile consecutive elements, of which
 * only the tiles in use take memory. A directory gives each tile of the grid its place in one pool; the first
 * kConstants places are shared constant tiles (all zeros, all ones...) that many tiles of the grid may point to, and
 * never change. A tile given back goes on a free list and is handed out again before the pool grows, so a grid whose
 * mixed tiles come and go (a moving robot's footprint, a scan's watch) does not grow without bound (issue 29).
 */
template <class Element, std::size_t kPerTile, std::uint32_t kConstants>
class TilePool
{
public:
  /// @brief A grid of `cell_count` cells, every tile on constant 0; constant c is filled with fills[c].
  void assign(std::size_t cell_count, const Element (&fills)[kConstants])
  {
    release();
    dir_.assign((cell_count + kPerTile - 1) / kPerTile, 0);
    pool_.resize(kConstants * kPerTile);
    for (std::uint32_t c = 0; c < kConstants; ++c)
    {
      std::fill_n(pool_.begin() + c * kPerTile, kPerTile, fills[c]);
    }
  }
  /// @brief No cells (and no memory).
  void release()
  {
    std::vector<std::uint32_t>().swap(dir_);
    std::vector<Element>().swap(pool_);
    std::vector<std::uint32_t>().swap(free_);
  }
  /// @return the element of a cell (in whichever tile, constant or not, its tile points to)
  const Element& at(std::size_t cell) const { return pool_[dir_[cell / kPerTile] * kPerTile + cell % kPerTile]; }
  /// @return the directory entry of a cell's tile: < kConstants for a constant tile
  std::uint32_t& slot(std::size_t cell) { return dir_[cell / kPerTile]; }
  /// @return the element of a cell in a tile in use (slot(cell) >= kConstants)
  Element& inTile(std::uint32_t tile, std::size_t cell) { return pool_[tile * kPerTile + cell % kPerTile]; }
  const Element* tileData(std::uint32_t tile) const { return &pool_[tile * kPerTile]; }
  /// @return a tile of the pool for one tile of the grid, filled with `fill` (reused from the free list when any)
  std::uint32_t newTile(Element fill)
  {
    std::uint32_t tile = 0;
    if (!free_.empty())
    {
      tile = free_.back();
      free_.pop_back();
    }
    else
    {
      tile = static_cast<std::uint32_t>(pool_.size() / kPerTile);
      pool_.resize(pool_.size() + kPerTile);
    }
    std::fill_n(pool_.begin() + tile * kPerTile, kPerTile, fill);
    return tile;
  }
  /// @brief Points a grid tile (its directory entry `slot`) back at `constant`, its pool tile going on the free list.
  void giveBack(std::uint32_t& slot, std::uint32_t constant)
  {
    free_.push_back(slot);
    slot = constant;
  }
  /// @return the tiles in use (not counting the constants)
  std::size_t tilesInUse() const { return pool_.empty() ? 0 : pool_.size() / kPerTile - kConstants - free_.size(); }
  /// @return the heap it holds: directory, tiles (with what their vectors reserved) and the free list
  std::size_t bytes() const
  {
    return dir_.capacity() * sizeof(std::uint32_t) + pool_.capacity() * sizeof(Element) +
           free_.capacity() * sizeof(std::uint32_t);
  }
  void swap(TilePool& other)
  {
    dir_.swap(other.dir_);
    pool_.swap(other.pool_);
    free_.swap(other.free_);
  }

private:
  std::vector<std::uint32_t> dir_;   ///< per tile of the grid: its place in pool_ (< kConstants: a constant)
  std::vector<Element> pool_;        ///< the tiles, kPerTile elements each; the first kConstants are the constants
  std::vector<std::uint32_t> free_;  ///< tiles of pool_ given back
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_TILE_POOL_H
