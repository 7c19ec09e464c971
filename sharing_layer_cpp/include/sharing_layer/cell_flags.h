#ifndef SHARING_LAYER_CELL_FLAGS_H
#define SHARING_LAYER_CELL_FLAGS_H

#include <cstddef>
#include <cstdint>
#include <vector>

#include "sharing_layer/scan_update.h"

namespace sharing_layer
{
/**
 * @brief One byte per cell of yes/no facts that several passes read in the same loop, kept together so that a scan
 * touches one byte per cell, not one array per fact. Who owns which bit:
 * - ScanWatch::kFlaggedWatched: a present cell of a shared obstacle (FleetObstacles sets it, kept between scans);
 * - the scan's own scratch bits, during applyScan only (it leaves them as it found them);
 * - kShareable and kRemembered: the cell is in ObservedCells' shareable list or trigger memory (kept with them);
 * - kSteady: a growth candidate of the current scan (ScanPass sets it and clears it before it returns).
 */
class CellFlags
{
public:
  static constexpr std::uint8_t kSteady = 0x80;
  static constexpr std::uint8_t kRemembered = 0x40;
  static constexpr std::uint8_t kShareable = 0x20;
  static_assert(((kSteady | kRemembered | kShareable) & ~ScanWatch::kOwnerBits) == 0,
                "the layer's own cell flags must be owner bits of the scan's scratch");

  /// @brief cell_count cells, no bit set.
  void assign(std::size_t cell_count) { bytes_.assign(cell_count, 0); }
  bool has(std::uint32_t index, std::uint8_t bit) const { return (bytes_[index] & bit) != 0; }
  void set(std::uint32_t index, std::uint8_t bit) { bytes_[index] |= bit; }
  void clear(std::uint32_t index, std::uint8_t bit) { bytes_[index] &= static_cast<std::uint8_t>(~bit); }
  std::uint8_t* data() { return bytes_.data(); }
  const std::uint8_t* data() const { return bytes_.data(); }
  std::size_t size() const { return bytes_.size(); }
  std::size_t bytes() const { return bytes_.capacity(); }
  void swap(CellFlags& other) { bytes_.swap(other.bytes_); }

private:
  std::vector<std::uint8_t> bytes_;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_CELL_FLAGS_H
