#ifndef FLEET_NAV_INFLATION_H
#define FLEET_NAV_INFLATION_H

#include <cstdint>
#include <vector>

namespace fleet_nav
{
/// @brief costmap_2d InflationLayer parameters, in metres.
struct InflationParams
{
  double resolution = 0.05;         ///< metres per cell
  double inscribed_radius = 0.325;  ///< from the footprint; cells this close to an obstacle get 253
  double inflation_radius = 0.55;   ///< cells farther than this from every obstacle are not inflated
  double cost_scaling_factor = 10.0;

  /// @throws std::invalid_argument naming the parameter and its value
  void validate() const;
};

/**
 * @brief costmap_2d's inflation with an exact Euclidean distance transform (Felzenszwalb–Huttenlocher):
 * lethal (254) cells stay lethal, cells within inscribed_radius get 253, cells within inflation_radius
 * get 252 * exp(-cost_scaling_factor * (d - inscribed_radius)), and the result never lowers a cost.
 *
 * Distances are whole-cell Euclidean distances between cell centres, like costmap_2d's cached
 * distance table. Unknown (255) cells stay unknown unless inflation makes them inscribed or lethal,
 * as costmap_2d does with inflate_unknown false.
 */
class Inflator
{
public:
  /// @throws std::invalid_argument on bad parameters
  explicit Inflator(const InflationParams& params);

  const InflationParams& params() const { return params_; }
  /// @return the inflation radius in whole cells
  unsigned int cellRadius() const { return cell_radius_; }
  /// @return the cost costmap_2d gives a cell at this many cells from the nearest obstacle
  std::uint8_t costAtDistance(double distance_cells) const;

  /**
   * @brief Inflates master into out over the window [min_x, max_x) x [min_y, max_y) (cells, clipped to
   * the grid); obstacles up to cellRadius() outside the window count. Cells outside the window are
   * not written. @throws std::invalid_argument when a pointer is null or the grid is empty
   */
  void inflate(const std::uint8_t* master, unsigned int size_x, unsigned int size_y, std::uint8_t* out,
               unsigned int min_x, unsigned int min_y, unsigned int max_x, unsigned int max_y);

  /// @brief Inflates the whole grid.
  void inflateAll(const std::uint8_t* master, unsigned int size_x, unsigned int size_y, std::uint8_t* out)
  {
    inflate(master, size_x, size_y, out, 0, 0, size_x, size_y);
  }

private:
  InflationParams params_;
  unsigned int cell_radius_ = 0;
  std::vector<std::uint8_t> cost_by_sq_distance_;  ///< cost for each squared cell distance up to radius^2
  std::vector<double> dist_;                        ///< squared distances over the padded window
  std::vector<double> f_, d_, z_;                   ///< 1-D transform buffers
  std::vector<int> v_;
};

}  // namespace fleet_nav

#endif  // FLEET_NAV_INFLATION_H
