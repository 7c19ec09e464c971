// What the plugin tests read from /diagnostics: the last status of each name, waited for while spinning.
#ifndef SHARING_LAYER_PLUGIN_TEST_DIAGNOSTICS_LISTENER_H
#define SHARING_LAYER_PLUGIN_TEST_DIAGNOSTICS_LISTENER_H

#include <exception>
#include <functional>
#include <map>
#include <string>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <ros/ros.h>

namespace sharing_layer_test
{
/// The last status of each name on /diagnostics.
struct DiagnosticsListener
{
  std::map<std::string, diagnostic_msgs::DiagnosticStatus> latest;
  ros::Subscriber sub;

  DiagnosticsListener()
  {
    sub = ros::NodeHandle().subscribe<diagnostic_msgs::DiagnosticArray>(
        "/diagnostics", 100, [this](const diagnostic_msgs::DiagnosticArray::ConstPtr& msg) {
          for (const diagnostic_msgs::DiagnosticStatus& status : msg->status)
          {
            latest[status.name] = status;
          }
        });
  }

  /// Spins (running `step` each round) until the status `name` satisfies `ok`, at most 15 s.
  bool waitFor(const std::string& name, const std::function<bool(const diagnostic_msgs::DiagnosticStatus&)>& ok,
               const std::function<void()>& step = [] {})
  {
    const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(15.0);
    while (ros::WallTime::now() < end)
    {
      step();
      ros::spinOnce();
      const auto it = latest.find(name);
      if (it != latest.end() && ok(it->second))
      {
        return true;
      }
      ros::WallDuration(0.02).sleep();
    }
    return false;
  }

  std::string describe(const std::string& name) const
  {
    const auto it = latest.find(name);
    if (it == latest.end())
    {
      return "no status named '" + name + "' on /diagnostics";
    }
    std::string text = "level " + std::to_string(it->second.level) + " '" + it->second.message + "':";
    for (const diagnostic_msgs::KeyValue& kv : it->second.values)
    {
      text += " [" + kv.key + ": " + kv.value + "]";
    }
    return text;
  }
};

inline std::string valueOf(const diagnostic_msgs::DiagnosticStatus& status, const std::string& key)
{
  for (const diagnostic_msgs::KeyValue& kv : status.values)
  {
    if (kv.key == key)
    {
      return kv.value;
    }
  }
  return "(no " + key + ")";
}

inline long countOf(const diagnostic_msgs::DiagnosticStatus& status, const std::string& key)
{
  try
  {
    return std::stol(valueOf(status, key));
  }
  catch (const std::exception&)
  {
    return -1;
  }
}

inline bool contains(const std::string& text, const std::string& part)
{
  return text.find(part) != std::string::npos;
}
}  // namespace sharing_layer_test

#endif  // SHARING_LAYER_PLUGIN_TEST_DIAGNOSTICS_LISTENER_H
