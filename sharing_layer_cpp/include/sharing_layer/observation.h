#ifndef SHARING_LAYER_OBSERVATION_H
#define SHARING_LAYER_OBSERVATION_H

#include <cstdint>
#include <limits>
#include <vector>

namespace sharing_layer
{
/// @brief A point in the grid's frame, metres.
struct Point3
{
  double x = 0.0;
  double y = 0.0;
  double z = 0.0;
};

/// @brief One sensor reading: its origin and its endpoints, already in the grid's frame
/// (costmap_2d's Observation without the buffer bookkeeping).
struct Observation
{
  Point3 origin;
  std::vector<Point3> points;
};

/// @brief costmap_2d ObstacleLayer limits for marking and clearing.
struct ScanLimits
{
  double obstacle_range = 2.5;        ///< endpoints closer than this are marked (m)
  double raytrace_range = 3.0;        ///< cells closer than this on a beam are cleared (m)
  double min_obstacle_height = 0.0;   ///< points below are ignored for marking and clearing (m)
  double max_obstacle_height = 2.0;   ///< points above are ignored for marking and clearing (m)
  /// Points above are cleared along but not marked (m): costmap_2d ObstacleLayer's layer-level
  /// max_obstacle_height, which dynamic_reconfigure changes (its sources' heights filter both, as the two above).
  double max_marking_height = std::numeric_limits<double>::infinity();
  /// costmap_2d's per-source `marking` and `clearing`: a source may only mark (no raytracing) or only clear
  /// (its endpoints are not marked, though one in a watched cell is still evidence that the cell is occupied).
  bool marking = true;
  bool clearing = true;

  /// @throws std::invalid_argument naming the field when a range is negative or not finite,
  ///         or min_obstacle_height > max_obstacle_height
  void validate() const;
};

/// @brief A rectangle of cells, both ends inclusive.
struct CellRect
{
  int min_x = 0;
  int min_y = 0;
  int max_x = -1;
  int max_y = -1;

  bool empty() const { return max_x < min_x || max_y < min_y; }
  bool contains(int x, int y) const { return x >= min_x && x <= max_x && y >= min_y && y <= max_y; }
};

/// @brief What one scan did to a grid.
struct ScanTouch
{
  bool origin_in_map = true;            ///< false: nothing was cleared (costmap_2d skips raytracing then)
  /// World box of what the scan touched, exactly as costmap_2d's ObstacleLayer grows its update bounds: the
  /// sensor origin and each beam's (map-clipped) endpoint pulled in to raytrace_range when clearing ran, and
  /// every marked point. A layer reports this box, not a fixed range around the sensor: later layers (inflation
  /// above all) and the master merge work over it. Empty (min > max) when the scan touched nothing.
  double min_x = 1e300;
  double min_y = 1e300;
  double max_x = -1e300;
  double max_y = -1e300;
  bool touchedNothing() const { return max_x < min_x || max_y < min_y; }
  void touchPoint(double x, double y)
  {
    min_x = x < min_x ? x : min_x;
    min_y = y < min_y ? y : min_y;
    max_x = x > max_x ? x : max_x;
    max_y = y > max_y ? y : max_y;
  }
  std::size_t rejected_points = 0;      ///< non-finite points, ignored
  std::size_t height_filtered = 0;      ///< points outside the height limits, ignored
  std::vector<std::uint32_t> marked;    ///< cells set lethal by this scan, sorted, unique
  /// Cells inside the watched rectangles that this scan cleared and did not mark again, sorted, unique.
  std::vector<std::uint32_t> watched_cleared;
  /// Subset of watched_cleared passed by a beam whose endpoint lies at least the watch's free_margin
  /// beyond the cell, and holding no endpoint of this scan: evidence of free space, sorted, unique.
  std::vector<std::uint32_t> watched_free;
  /// Watched cells holding an endpoint of this scan at any range (also beyond obstacle_range, where
  /// nothing is marked): evidence of occupancy, sorted, unique.
  std::vector<std::uint32_t> watched_hit;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_OBSERVATION_H
