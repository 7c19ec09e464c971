// The layer where the benches need it as a node of its own (issue 48): a move_base stand-in that holds the global
// costmap only. Like move_base it builds costmap_2d::Costmap2DROS("global_costmap") from its parameters (the plugins
// they list, the sharing layer among them), lets it update in its own thread at update_frequency, and spins every
// other callback in the main thread (ros::spin), the shared obstacles' among them. Nothing else of move_base runs, so
// the process's CPU time is the costmap's.
//
// A probe for latencies into the costmap: cells published on ~watch (std_msgs/UInt32MultiArray, master cell indexes)
// are looked at in the master 200 times a second, and the first time each one reads lethal a line
//   lethal <cell index> <wall time, s since the epoch>
// goes to standard output. Once the costmap is up: "ready".
//
//   rosrun sharing_layer_cpp layer_host __name:=move_base __ns:=robot_1   (parameters as move_base's global costmap)
#include <algorithm>
#include <cstdio>
#include <mutex>
#include <unordered_set>
#include <vector>

#include <costmap_2d/cost_values.h>
#include <costmap_2d/costmap_2d_ros.h>
#include <ros/ros.h>
#include <std_msgs/UInt32MultiArray.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

namespace
{
/// Watched master cells, and the first time each read lethal.
class Probe
{
public:
  explicit Probe(costmap_2d::Costmap2DROS& costmap) : costmap_(costmap) {}

  void watch(const std_msgs::UInt32MultiArray::ConstPtr& msg)
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (std::uint32_t cell : msg->data)
    {
      if (seen_.count(cell) == 0)
      {
        watched_.push_back(cell);
      }
    }
  }

  void look(const ros::WallTimerEvent&)
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (watched_.empty())
    {
      return;
    }
    costmap_2d::Costmap2D* master = costmap_.getCostmap();
    std::vector<std::uint32_t> lethal;
    {
      boost::unique_lock<costmap_2d::Costmap2D::mutex_t> master_lock(*master->getMutex());
      const std::size_t cells = static_cast<std::size_t>(master->getSizeInCellsX()) * master->getSizeInCellsY();
      const unsigned char* costs = master->getCharMap();
      for (std::uint32_t cell : watched_)
      {
        if (cell < cells && costs[cell] == costmap_2d::LETHAL_OBSTACLE)
        {
          lethal.push_back(cell);
        }
      }
    }
    if (lethal.empty())
    {
      return;
    }
    const double now = ros::WallTime::now().toSec();
    for (std::uint32_t cell : lethal)
    {
      std::printf("lethal %u %.6f\n", cell, now);
      seen_.insert(cell);
    }
    std::fflush(stdout);
    watched_.erase(std::remove_if(watched_.begin(), watched_.end(),
                                  [this](std::uint32_t cell) { return seen_.count(cell) != 0; }),
                   watched_.end());
  }

private:
  costmap_2d::Costmap2DROS& costmap_;
  std::mutex mutex_;
  std::vector<std::uint32_t> watched_;
  std::unordered_set<std::uint32_t> seen_;
};
}  // namespace

int main(int argc, char** argv)
{
  ros::init(argc, argv, "move_base");
  ros::NodeHandle private_nh("~");
  tf2_ros::Buffer buffer(ros::Duration(10.0));
  tf2_ros::TransformListener listener(buffer);
  costmap_2d::Costmap2DROS costmap("global_costmap", buffer);
  costmap.start();
  Probe probe(costmap);
  ros::Subscriber watch = private_nh.subscribe("watch", 100, &Probe::watch, &probe);
  ros::WallTimer look = private_nh.createWallTimer(ros::WallDuration(0.005), &Probe::look, &probe);
  std::printf("ready\n");
  std::fflush(stdout);
  ros::spin();
  return 0;
}
