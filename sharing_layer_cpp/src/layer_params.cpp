#include "sharing_layer/layer_params.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace sharing_layer
{
void LayerParams::validate() const
{
  limits.validate();
  if (static_tolerance < 0)
  {
    throw std::invalid_argument("static_tolerance must be >= 0 cells, got " + std::to_string(static_tolerance));
  }
  if (!std::isfinite(trigger_debounce) || trigger_debounce < 0.0)
  {
    throw std::invalid_argument("trigger_debounce must be finite and >= 0 s, got " + std::to_string(trigger_debounce));
  }
  if (!std::isfinite(rectangle_padding) || rectangle_padding < 0.0)
  {
    throw std::invalid_argument("rectangle_padding must be finite and >= 0 m, got " +
                                std::to_string(rectangle_padding));
  }
  if (cluster_gap == 0 || cluster_gap > 50)
  {
    throw std::invalid_argument("cluster_gap must be 1..50 cells, got " + std::to_string(cluster_gap));
  }
  if (max_update_cells == 0)
  {
    throw std::invalid_argument("max_update_cells must be > 0");
  }
  if (robot_name.empty())
  {
    throw std::invalid_argument("robot_name must not be empty");
  }
  const auto check_non_negative = [](double value, const char* name, const char* unit) {
    if (!std::isfinite(value) || value < 0.0)
    {
      throw std::invalid_argument(std::string(name) + " must be finite and >= 0 " + unit + ", got " +
                                  std::to_string(value));
    }
  };
  check_non_negative(clearing_margin, "clearing_margin", "m");
  check_non_negative(trigger_memory, "trigger_memory", "s");
  check_non_negative(clearing_time, "clearing_time", "s");
  check_non_negative(trigger_radius, "trigger_radius", "m");
  check_non_negative(inscribed_radius, "inscribed_radius", "m");
  if (clearing_neighbours > 1000)
  {
    throw std::invalid_argument("clearing_neighbours must be 0..1000 beams, got " +
                                std::to_string(clearing_neighbours));
  }
  if (clearing_scans == 0 || clearing_scans > 1000)
  {
    throw std::invalid_argument("clearing_scans must be 1..1000 scans, got " + std::to_string(clearing_scans));
  }
  check_non_negative(lease_renewal_interval, "lease_renewal_interval", "s");
}

}  // namespace sharing_layer
