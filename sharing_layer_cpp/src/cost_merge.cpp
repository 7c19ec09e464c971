#include "sharing_layer/cost_merge.h"

#include "sharing_layer/cost_values.h"

namespace sharing_layer
{
namespace
{
template <class Rule>
void mergeRows(const std::uint8_t* layer, std::uint8_t* master, const MergeWindow& w, Rule rule)
{
  if (w.max_i <= w.min_i || w.max_j <= w.min_j)
  {
    return;
  }
  const std::size_t width = static_cast<std::size_t>(w.max_i - w.min_i);
  for (int j = w.min_j; j < w.max_j; ++j)
  {
    const std::size_t start = static_cast<std::size_t>(j) * w.row_size + static_cast<std::size_t>(w.min_i);
    const std::uint8_t* __restrict from = layer + start;
    std::uint8_t* __restrict to = master + start;
    for (std::size_t k = 0; k < width; ++k)
    {
      to[k] = rule(to[k], from[k]);
    }
  }
}
}  // namespace

static_assert(NO_INFORMATION == 255, "mergeMax counts NO_INFORMATION as -1 in 8-bit arithmetic");

void mergeMax(const std::uint8_t* layer, std::uint8_t* master, const MergeWindow& window)
{
  mergeRows(layer, master, window, [](std::uint8_t old_cost, std::uint8_t cost) {
    const std::uint8_t a = static_cast<std::uint8_t>(old_cost + 1), b = static_cast<std::uint8_t>(cost + 1);
    return static_cast<std::uint8_t>((a > b ? a : b) - 1);
  });
}

void mergeOverwrite(const std::uint8_t* layer, std::uint8_t* master, const MergeWindow& window)
{
  mergeRows(layer, master, window,
            [](std::uint8_t old_cost, std::uint8_t cost) { return cost == NO_INFORMATION ? old_cost : cost; });
}
}  // namespace sharing_layer
