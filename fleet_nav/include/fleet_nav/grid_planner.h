#ifndef FLEET_NAV_GRID_PLANNER_H
#define FLEET_NAV_GRID_PLANNER_H

#include <cstdint>
#include <string>
#include <vector>

namespace fleet_nav
{
/// @brief Cost model of the planner (global_planner's names and defaults).
struct PlannerParams
{
  double neutral_cost = 50.0;          ///< cost of a free step of one cell
  double cost_factor = 3.0;            ///< added cost per unit of cell cost
  std::uint8_t lethal_cost = 253;      ///< cells at or above this are not entered (inscribed and lethal)
  bool allow_unknown = true;           ///< unknown (255) cells may be crossed, at unknown_cost
  std::uint8_t unknown_cost = 200;     ///< cell cost assumed for unknown cells when allowed
  unsigned int escape_cells = 10;      ///< a start in inscribed cells may cross inscribed cells this close to it

  /// @throws std::invalid_argument naming the parameter and its value
  void validate() const;
};

/// @brief A rectangle of cells [min_x, max_x) x [min_y, max_y) the search must stay in.
struct CellWindow
{
  unsigned int min_x = 0, min_y = 0, max_x = 0, max_y = 0;
};

/// @brief Why a plan failed, for the caller's log line.
enum class PlanStatus
{
  Ok,
  StartOffGrid,
  GoalOffGrid,
  GoalBlocked,
  NoPath
};

/// @return a short English description of a status
std::string describe(PlanStatus status);

/**
 * @brief A* on the 8-connected cell grid of a costmap, with global_planner's step cost
 * (neutral_cost + cost_factor * cost) times the step length; diagonal steps never cut the corner of
 * a blocked cell. The start may lie in an inscribed (253) cell: the search may leave through
 * inscribed cells within escape_cells (Chebyshev) of the start, so a robot pressed against a wall
 * can still plan; never through a lethal cell, and never along a long inscribed ridge.
 * Buffers are kept between calls; one planner per thread.
 */
class GridPlanner
{
public:
  /// @throws std::invalid_argument on bad parameters
  explicit GridPlanner(const PlannerParams& params = PlannerParams());

  const PlannerParams& params() const { return params_; }

  /**
   * @brief Plans from start to goal (flat indexes y * size_x + x). On success fills path with the
   * cell indexes from start to goal inclusive. With a window, only cells inside it are searched.
   * @throws std::invalid_argument when costs is null or the grid is empty
   */
  PlanStatus makePlan(const std::uint8_t* costs, unsigned int size_x, unsigned int size_y, std::uint32_t start,
                      std::uint32_t goal, std::vector<std::uint32_t>& path, const CellWindow* window = nullptr);

  /// @return cells expanded by the last makePlan call
  std::size_t lastExpansions() const { return expansions_; }

  /// @return the path cost of the last successful plan (in cost units)
  double lastCost() const { return last_cost_; }

private:
  double stepCost(std::uint8_t cost) const;
  bool blocked(std::uint8_t cost) const;

  PlannerParams params_;
  std::vector<float> g_;
  std::vector<std::uint32_t> parent_;
  std::vector<std::uint32_t> touched_;
  std::vector<std::uint8_t> state_;  ///< 0 unseen, 1 open, 2 closed
  std::size_t expansions_ = 0;
  double last_cost_ = 0.0;
};

/**
 * @brief First position along path (from index `from`, at most `count` cells) whose cost is at or
 * above lethal_cost; -1 when none is.
 */
long firstBlocked(const std::uint8_t* costs, std::size_t cell_count, const std::vector<std::uint32_t>& path,
                  std::size_t from, std::size_t count, std::uint8_t lethal_cost);

}  // namespace fleet_nav

#endif  // FLEET_NAV_GRID_PLANNER_H
