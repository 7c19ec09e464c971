#ifndef SHARING_LAYER_CELL_FLAGS_H
#define SHARING_LAYER_CELL_FLAGS_H

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <utility>

#include "sharing_layer/tile_pool.h"

namespace sharing_layer
{
/**
 * @brief A byte of yes/no facts per cell that several passes read in the same loop, kept together so that a scan
 * reads one byte per cell, not one array per fact. Who owns which bit:
 * - kFlaggedWatched: a present cell of a shared obstacle (FleetObstacles sets it, kept between scans);
 * - the scan's own bits (kScanBits), during applyScan only (it leaves them as it found them);
 * - kShareable and kRemembered: the cell is in ObservedCells' shareable list or trigger memory (kept with them).
 *
 * Every bit is set on few cells (those of shared obstacles, of this robot's recent marks, of a scan's watch), so the
 * bytes are kept in tiles of kTileCells consecutive cells, and only a tile with a bit set takes memory: the grid
 * costs a directory of 4 bytes per tile (1/32 byte per cell) plus kTileCells bytes per tile in use (issue 29). A
 * cell of a tile not in use reads 0 (a shared tile of zeros); a tile whose last bit is cleared is given back.
 */
class CellFlags
{
public:
  static constexpr std::uint8_t kFlaggedWatched = 0x01;
  static constexpr std::uint8_t kScanBits = 0x1E;  ///< applyScan's (see scan_update.cpp)
  static constexpr std::uint8_t kRemembered = 0x40;
  static constexpr std::uint8_t kShareable = 0x20;
  /// applyScan leaves these alone (kRemembered, kShareable and one spare)
  static constexpr std::uint8_t kOwnerBits = 0xE0;
  static constexpr std::size_t kTileCells = 128;

  /// @brief cell_count cells, no bit set.
  void assign(std::size_t cell_count)
  {
    size_ = cell_count;
    tiles_.assign(cell_count, { 0 });  // constant 0: the shared zeros
  }
  /// @brief No cells (and no memory).
  void release()
  {
    tiles_.release();
    size_ = 0;
  }
  /// @return the cell's byte (0 in a tile not in use)
  std::uint8_t get(std::uint32_t index) const { return tiles_.at(index); }
  bool has(std::uint32_t index, std::uint8_t bit) const { return (get(index) & bit) != 0; }
  void set(std::uint32_t index, std::uint8_t bits)
  {
    std::uint32_t& tile = tiles_.slot(index);
    if (tile == kZeros)
    {
      if (bits == 0)
      {
        return;
      }
      tile = tiles_.newTile(0);
    }
    tiles_.inTile(tile, index) |= bits;
  }
  void clear(std::uint32_t index, std::uint8_t bits)
  {
    std::uint32_t& tile = tiles_.slot(index);
    if (tile == kZeros)
    {
      return;
    }
    std::uint8_t& byte = tiles_.inTile(tile, index);
    byte &= static_cast<std::uint8_t>(~bits);
    if (byte == 0)
    {
      settle(tile);
    }
  }
  std::size_t size() const { return size_; }
  /// @return the heap it holds: directory, tiles (with what their vectors reserved) and the free list
  std::size_t bytes() const { return tiles_.bytes(); }
  /// @return the tiles in use
  std::size_t tilesInUse() const { return tiles_.tilesInUse(); }
  void swap(CellFlags& other)
  {
    tiles_.swap(other.tiles_);
    std::swap(size_, other.size_);
  }

private:
  static constexpr std::uint32_t kZeros = 0;  ///< the shared tile of zeros: a tile not in use

  /// @brief Gives a tile (at `slot` in the directory) back once none of its cells holds a bit.
  void settle(std::uint32_t& slot)
  {
    const std::uint8_t* bytes = tiles_.tileData(slot);
    for (std::size_t i = 0; i < kTileCells; i += sizeof(std::uint64_t))
    {
      std::uint64_t w = 0;
      std::memcpy(&w, bytes + i, sizeof(w));
      if (w != 0)
      {
        return;
      }
    }
    tiles_.giveBack(slot, kZeros);
  }

  TilePool<std::uint8_t, kTileCells, 1> tiles_;
  std::size_t size_ = 0;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_CELL_FLAGS_H
