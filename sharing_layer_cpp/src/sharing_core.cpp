#include "sharing_layer/sharing_core.h"

#include <limits>
#include <stdexcept>
#include <string>

#include "sharing_layer/cost_values.h"

namespace sharing_layer
{
SharingCore::SharingCore(const GridGeometry& geometry, const LayerParams& params)
  : params_(params)
  , triggers_(params.trigger_debounce)
  , fleet_(geometry.cellCount())
  , fleet_robots_(geometry)
{
  params_.validate();
  obstacles_ = CostGrid(GridGeometry(geometry.resolution, geometry.origin_x, geometry.origin_y, geometry.size_x,
                                     geometry.size_y),
                        FREE_SPACE);
  flags_.assign(geometry.cellCount());
}

std::size_t SharingCore::perCellBytes() const
{
  return flags_.bytes() + fleet_.bytes() + statics_.bytes() + fleet_robots_.gridBytes();
}

// --- The a-priori map ---

void SharingCore::setStaticMap(const std::uint8_t* costs, std::size_t cost_count)
{
  statics_.setWalls(geometry(), costs, cost_count, params_.static_tolerance, params_.static_occupied_cost);
  observed_.dropStatic(statics_, flags_);
}

void SharingCore::setUnknownMap(const std::uint8_t* unknown, std::size_t cell_count)
{
  statics_.setUnknown(geometry(), unknown, cell_count, params_.static_tolerance);
  observed_.dropStatic(statics_, flags_);
}

// --- The scan pass ---

ScanOutcome SharingCore::processScan(const Observation& observation, double now_s, const ScanLimits& limits)
{
  ScanParts parts = scanParts();
  return scan_.run(observation, now_s, limits, parts);
}

// --- The triggers ---

std::vector<Proposal> SharingCore::propose(double robot_x, double robot_y, bool use_memory) const
{
  return triggers_.propose(robot_x, robot_y, use_memory, triggerInputs());
}

TriggerReport SharingCore::trigger(TriggerSource source, double now_s, double robot_x, double robot_y)
{
  return triggers_.trigger(source, now_s, robot_x, robot_y, fleet_robots_, triggerInputs());
}

void SharingCore::setPlan(const std::vector<std::pair<double, double>>& poses)
{
  if (!triggers_.setPlan(poses))
  {
    scan_.last().new_marked.clear();
    scan_.last().far_hits.clear();
  }
}

TriggerReport SharingCore::checkPlan(double robot_x, double robot_y, double now_s)
{
  return triggers_.checkPlan(robot_x, robot_y, now_s, fleet_robots_, triggerInputs());
}

void SharingCore::setInscribedRadius(double radius_m)
{
  LayerParams changed = params_;
  changed.inscribed_radius = radius_m;
  changed.validate();
  params_ = changed;
}

void SharingCore::setParams(const LayerParams& params)
{
  params.validate();
  triggers_.setDebounce(params.trigger_debounce);  // validated: cannot throw
  const bool tolerance_changed = params.static_tolerance != params_.static_tolerance;
  params_ = params;
  if (tolerance_changed)
  {
    statics_.setTolerance(geometry(), params_.static_tolerance);
    observed_.dropStatic(statics_, flags_);
  }
}

std::vector<std::uint32_t> SharingCore::rememberedCells() const
{
  return observed_.rememberedSorted();
}

std::vector<std::uint32_t> SharingCore::shareableCells() const
{
  return observed_.shareableSorted();
}

// --- The fleet's obstacles ---

ApplyResult SharingCore::applyShared(const ObstacleUpdate& update, double now_s)
{
  return fleet_.apply(update, now_s, geometry(), params_.max_update_cells, observed_, flags_);
}

bool SharingCore::expire(const std::string& uuid)
{
  return fleet_.expire(uuid, geometry());
}

std::vector<std::uint32_t> SharingCore::sharedCells(const std::string& uuid) const
{
  return fleet_.presentCells(uuid);
}

void SharingCore::drawShared(std::uint8_t* master, std::size_t cell_count) const
{
  drawShared(master, cell_count, 0, 0, static_cast<int>(geometry().size_x), static_cast<int>(geometry().size_y));
}

void SharingCore::drawShared(std::uint8_t* master, std::size_t cell_count, int min_i, int min_j, int max_i,
                             int max_j) const
{
  if (cell_count != geometry().cellCount())
  {
    throw std::invalid_argument("drawShared: master grid has " + std::to_string(cell_count) + " cells, layer " +
                                geometry().describe());
  }
  fleet_.draw(master, geometry(), min_i, min_j, max_i, max_j);
}

WorldBounds SharingCore::takeDirtyBounds()
{
  return fleet_.takeDirtyBounds();
}

// --- The grid frame ---

void SharingCore::useObstacleGrid(std::uint8_t* costs, std::uint8_t default_value)
{
  if (costs == nullptr)
  {
    throw std::invalid_argument("SharingCore::useObstacleGrid: no buffer for " + geometry().describe());
  }
  obstacles_ = CostGrid::view(geometry(), costs, default_value);
}

MoveReport SharingCore::moveTo(const GridGeometry& geometry, bool keep_observations, std::uint8_t* costs,
                               std::uint8_t default_value)
{
  if (costs == nullptr)
  {
    throw std::invalid_argument("SharingCore::moveTo: no buffer for " + geometry.describe());
  }
  return moveGrid(geometry, keep_observations, costs, default_value);
}

MoveReport SharingCore::moveTo(const GridGeometry& geometry, bool keep_observations)
{
  return moveGrid(geometry, keep_observations, nullptr, FREE_SPACE);
}

MoveReport SharingCore::moveGrid(const GridGeometry& geometry, bool keep_observations, std::uint8_t* costs,
                                 std::uint8_t default_value)
{
  MoveReport report;
  const CellMover mover(this->geometry(), geometry);
  // Allocate first: nothing changes when the new grid cannot be had.
  CostGrid obstacles =
      moveObstacleGrid(obstacles_, geometry, keep_observations, costs, default_value, report.obstacle_cells_kept);
  CellFlags flags;
  flags.assign(geometry.cellCount());

  observed_.moveTo(mover, keep_observations, flags);
  obstacles_ = std::move(obstacles);
  flags_.swap(flags);  // a fresh scratch: every present cell is flagged again at the next scan
  statics_.clear();    // no static sources on the new grid (set again)
  fleet_robots_.setGeometry(geometry);
  scan_.last().forgetMarks();
  fleet_.moveTo(mover, geometry, observed_, flags_, report);
  return report;
}

void SharingCore::resetObstacleLayer()
{
  obstacles_.reset();
  // What the robot saw before the reset is forgotten with it (the trigger memory and the plan trigger's newly
  // marked cells); shared obstacles and their monitoring state stay.
  observed_.forget(flags_);
  scan_.last().forgetMarks();
  scan_.last().origin_x = scan_.last().origin_y = std::numeric_limits<double>::quiet_NaN();
}

std::size_t SharingCore::clearObstaclesOutside(int x0, int y0, int x1, int y1)
{
  const std::size_t cleared = clearGridOutside(obstacles_, x0, y0, x1, y1);
  observed_.keepShareable(geometry(), flags_,
                          [&](unsigned int mx, unsigned int my) { return insideOpenWindow(mx, my, x0, y0, x1, y1); });
  return cleared;
}

}  // namespace sharing_layer
