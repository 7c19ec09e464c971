// The layer's grid and the core's: one obstacle grid shared with the core, kept in step when costmap_2d resizes or
// moves the master (a new map, the rolling window) and when the footprint changes. Members of SharingLayer; the
// cycle itself is in sharing_layer.cpp.
#include "sharing_layer.h"

#include <cmath>
#include <mutex>

namespace sharing_layer
{
GridGeometry SharingLayer::masterGeometry() const
{
  const costmap_2d::Costmap2D* master = layered_costmap_->getCostmap();
  return GridGeometry(master->getResolution(), master->getOriginX(), master->getOriginY(),
                      master->getSizeInCellsX(), master->getSizeInCellsY());
}

bool SharingLayer::sharesGridWithCore()
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  return core_ && core_->obstacleGrid().data() == costmap_;
}

bool SharingLayer::gridMatches(const GridGeometry& g) const
{
  return costmap_ != nullptr && getSizeInCellsX() == g.size_x && getSizeInCellsY() == g.size_y;
}

void SharingLayer::shareGridWithCore()
{
  // One obstacle grid: the core clears and marks this layer's own costmap_ (no second grid, no copy per cycle).
  if (gridMatches(core_->geometry()))
  {
    core_->useObstacleGrid(costmap_, default_value_);
  }
  else
  {
    ROS_WARN("SharingLayer (%s): the layer's grid (%ux%u) differs from the master's (%s); the core keeps a grid of "
             "its own until the next resize",
             params_.robot_name.c_str(), getSizeInCellsX(), getSizeInCellsY(), core_->geometry().describe().c_str());
  }
}

MoveReport SharingLayer::moveCore(const GridGeometry& geometry, bool keep_observations)
{
  // ObstacleLayer has already resized (matchSize) or moved (updateOrigin) costmap_: the core takes it as it is.
  return gridMatches(geometry) ? core_->moveTo(geometry, keep_observations, costmap_, default_value_) :
                                 core_->moveTo(geometry, keep_observations);
}

void SharingLayer::rebuildCore()
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  const costmap_2d::Costmap2D* master = layered_costmap_->getCostmap();
  if (master->getSizeInCellsX() == 0 || master->getSizeInCellsY() == 0)
  {
    return;  // the static layer has no map yet; matchSize() calls again
  }
  core_.reset(new SharingCore(masterGeometry(), params_));
  shareGridWithCore();
  core_->fleetRobots().setParams(fleet_params_);
  applyUnknownMap();
  applyFleetRobots();
  // LayeredCostmap::resizeMap() blanks the master before calling matchSize(); the static layer writes
  // its map into the master only in the next updateCosts(), before ours. Take the a-priori map there.
  static_pending_ = true;
  pre_static_scans_.clear();
}

void SharingLayer::matchSize()
{
  ObstacleLayer::matchSize();
  {
    std::lock_guard<std::mutex> lock(core_mutex_);
    const costmap_2d::Costmap2D* master = layered_costmap_->getCostmap();
    if (core_ && master->getSizeInCellsX() > 0 && master->getSizeInCellsY() > 0)
    {
      // A new map (size, resolution or origin): shared obstacles stay where they are in the world. The layer's
      // own grid starts empty, as ObstacleLayer's does after resizeMap.
      const GridGeometry geometry = masterGeometry();
      const MoveReport report = moveCore(geometry, false);
      ROS_INFO("SharingLayer (%s): grid now %s; %zu shared obstacle(s) kept by world position, %zu of their "
               "cells off the new grid dropped (%zu obstacle(s) left with none)",
               params_.robot_name.c_str(), geometry.describe().c_str(), core_->sharedObstacles().size(),
               report.shared_cells_dropped, report.obstacles_out_of_grid);
      applyUnknownMap();
      static_pending_ = true;  // the static layer draws the new map into the master in the next updateCosts()
      pre_static_scans_.clear();
      return;
    }
  }
  rebuildCore();
}

void SharingLayer::followRollingWindow(double robot_x, double robot_y)
{
  // ObstacleLayer's rolling window: the layer's grid is centred on the robot (LayeredCostmap has moved the
  // master the same way), and the core's grid follows it. What the sensors marked and the shared obstacles stay
  // where they are in the world; what falls off is dropped, as Costmap2D::updateOrigin drops it.
  updateOrigin(robot_x - getSizeInMetersX() / 2, robot_y - getSizeInMetersY() / 2);
  std::lock_guard<std::mutex> lock(core_mutex_);
  if (!core_)
  {
    return;
  }
  const GridGeometry geometry = masterGeometry();
  const GridGeometry& current = core_->geometry();
  if (geometry.origin_x == current.origin_x && geometry.origin_y == current.origin_y &&
      geometry.size_x == current.size_x && geometry.size_y == current.size_y)
  {
    return;
  }
  const MoveReport report = moveCore(geometry, true);
  if (report.shared_cells_dropped > 0)
  {
    ROS_INFO_THROTTLE(10.0, "SharingLayer (%s): the rolling window left %zu cell(s) of shared obstacles behind "
                            "(%zu obstacle(s) now wholly outside it)",
                      params_.robot_name.c_str(), report.shared_cells_dropped, report.obstacles_out_of_grid);
  }
  // A rolling window has no a-priori map to tell walls from new obstacles: the layer keeps ObstacleLayer's
  // behaviour and the fleet's obstacles, and proposes nothing of its own (static_pending_ blocks the plan
  // trigger; onInitialize says so).
  static_pending_ = true;
  pre_static_scans_.clear();
}

void SharingLayer::onFootprintChanged()
{
  ObstacleLayer::onFootprintChanged();
  const double inscribed = layered_costmap_->getInscribedRadius();
  if (!inscribed_from_footprint_ || !(inscribed > 0.0) || !std::isfinite(inscribed))
  {
    return;
  }
  std::unique_lock<std::mutex> lock(core_mutex_);
  // costmap_2d sets the footprint more than once at start-up (padding), with radii that differ only in the
  // last bits: log a change a person would see.
  if (std::abs(inscribed - params_.inscribed_radius) > 1e-6)
  {
    ROS_INFO("SharingLayer %s (%s): plan trigger within the footprint's inscribed radius %.3f m of the plan",
             name_.c_str(), params_.robot_name.c_str(), inscribed);
  }
  params_.inscribed_radius = inscribed;
  if (core_)
  {
    core_->setInscribedRadius(inscribed);
  }
  lock.unlock();  // reconfigure() takes the server's mutex, then core_mutex_
  boost::recursive_mutex::scoped_lock reconfigure_lock(reconfigure_mutex_);
  if (reconfigure_server_)
  {
    reconfigure_config_.inscribed_radius = inscribed;  // shown in the server, not a change of the user's
    reconfigure_server_->updateConfig(reconfigure_config_);
  }
}
}  // namespace sharing_layer
