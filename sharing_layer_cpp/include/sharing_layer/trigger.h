#ifndef SHARING_LAYER_TRIGGER_H
#define SHARING_LAYER_TRIGGER_H

#include <limits>

namespace sharing_layer
{
/**
 * @brief Debounces the "cannot get past" signal.
 *
 * A stuck local planner reports failure at its control rate (10 Hz); only the first signal
 * of a burst fires. A burst ends when no signal came for longer than the window. Time going
 * backwards (a simulation restart) starts a new burst.
 */
class TriggerDebounce
{
public:
  /// @throws std::invalid_argument when window_s is negative or not finite
  explicit TriggerDebounce(double window_s = 2.0);

  /// @brief Registers a signal at now_s; @return true when it starts a new burst
  bool signal(double now_s);
  double window() const { return window_; }
  /// @return signals in the current burst, the last one included (1 right after a burst started)
  unsigned long burstSignals() const { return burst_signals_; }

private:
  double window_;
  double last_signal_ = -std::numeric_limits<double>::infinity();
  unsigned long burst_signals_ = 0;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_TRIGGER_H
