// sharing_msgs/SharedObstacle <-> the core's ObstacleUpdate, for the plugin and its bench.
#ifndef SHARING_LAYER_PLUGIN_MESSAGES_H
#define SHARING_LAYER_PLUGIN_MESSAGES_H

#include <stdexcept>
#include <string>

#include <ros/time.h>
#include <sharing_msgs/SharedObstacle.h>

#include "sharing_layer/shared_obstacle.h"

namespace sharing_layer
{
inline sharing_msgs::SharedObstacle toMessage(const ObstacleUpdate& update, const std::string& frame)
{
  sharing_msgs::SharedObstacle msg;
  msg.header.stamp = ros::Time(update.stamp);
  msg.header.frame_id = frame;
  msg.uuid = update.uuid;
  msg.marked_indexes = update.marked;
  msg.cleared_indexes = update.cleared;
  msg.deadline = update.deadline;
  msg.rectangle_shape = { static_cast<float>(update.rectangle.min_x), static_cast<float>(update.rectangle.min_y),
                          static_cast<float>(update.rectangle.max_x), static_cast<float>(update.rectangle.max_y) };
  msg.source = update.source;
  msg.resolution = static_cast<float>(update.geometry.resolution);
  msg.origin_x = update.geometry.origin_x;
  msg.origin_y = update.geometry.origin_y;
  msg.size_x = update.geometry.size_x;
  msg.size_y = update.geometry.size_y;
  msg.version = update.version;
  return msg;
}

/// @throws std::invalid_argument when the message cannot be a valid update
inline ObstacleUpdate fromMessage(const sharing_msgs::SharedObstacle& msg)
{
  if (msg.rectangle_shape.size() != 4)
  {
    throw std::invalid_argument("rectangle_shape has " + std::to_string(msg.rectangle_shape.size()) +
                                " values, expected 4");
  }
  ObstacleUpdate update;
  update.uuid = msg.uuid;
  update.marked = msg.marked_indexes;
  update.cleared = msg.cleared_indexes;
  update.deadline = msg.deadline;
  update.rectangle = Subsection(msg.rectangle_shape[0], msg.rectangle_shape[1], msg.rectangle_shape[2],
                                msg.rectangle_shape[3]);
  update.source = msg.source;
  update.geometry = GridGeometry(msg.resolution, msg.origin_x, msg.origin_y, msg.size_x, msg.size_y);
  update.version = msg.version;
  update.stamp = msg.header.stamp.toSec();
  return update;
}
}  // namespace sharing_layer

#endif  // SHARING_LAYER_PLUGIN_MESSAGES_H
