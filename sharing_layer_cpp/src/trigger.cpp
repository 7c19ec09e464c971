#include "sharing_layer/trigger.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace sharing_layer
{
TriggerDebounce::TriggerDebounce(double window_s) : window_(window_s)
{
  if (!std::isfinite(window_s) || window_s < 0.0)
  {
    throw std::invalid_argument("TriggerDebounce: trigger_debounce must be finite and >= 0, got " +
                                std::to_string(window_s));
  }
}

bool TriggerDebounce::signal(double now_s)
{
  if (!std::isfinite(now_s))
  {
    return false;
  }
  const bool fires = now_s < last_signal_ || now_s - last_signal_ > window_;
  last_signal_ = now_s;
  burst_signals_ = fires ? 1 : burst_signals_ + 1;
  return fires;
}

}  // namespace sharing_layer
