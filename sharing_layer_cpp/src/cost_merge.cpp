#include "sharing_layer/cost_merge.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "sharing_layer/cost_values.h"

namespace sharing_layer
{
namespace
{
static_assert(NO_INFORMATION == 255, "mergeMax counts NO_INFORMATION as -1 in 8-bit arithmetic");

/// The rules as types, so that each merge loop is compiled with its rule inlined (a function pointer was called once
/// per 16 cells at -O2).
struct MaxRule
{
  std::uint8_t operator()(std::uint8_t old_cost, std::uint8_t cost) const
  {
    const std::uint8_t a = static_cast<std::uint8_t>(old_cost + 1), b = static_cast<std::uint8_t>(cost + 1);
    return static_cast<std::uint8_t>((a > b ? a : b) - 1);
  }
#if defined(__SSE2__)
  // Sixteen cells per step with SSE2, which every x86-64 CPU has (the baseline ROS packages build for): GCC
  // vectorises the plain loop only at -O3 or with a cost model -O2 does not use, and a user's -O2 build would then
  // merge cell by cell (issue 48). The same rules as the scalar ones, lane by lane (test_cost_merge checks every pair
  // of costs through both).
  __m128i operator()(__m128i old_cost, __m128i cost) const
  {
    const __m128i one = _mm_set1_epi8(1);
    return _mm_sub_epi8(_mm_max_epu8(_mm_add_epi8(old_cost, one), _mm_add_epi8(cost, one)), one);
  }
#endif
};

struct OverwriteRule
{
  std::uint8_t operator()(std::uint8_t old_cost, std::uint8_t cost) const
  {
    return cost == NO_INFORMATION ? old_cost : cost;
  }
#if defined(__SSE2__)
  __m128i operator()(__m128i old_cost, __m128i cost) const
  {
    const __m128i unknown = _mm_cmpeq_epi8(cost, _mm_set1_epi8(static_cast<char>(NO_INFORMATION)));
    return _mm_or_si128(_mm_and_si128(unknown, old_cost), _mm_andnot_si128(unknown, cost));
  }
#endif
};

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
    const std::uint8_t* from = layer + start;
    std::uint8_t* to = master + start;
    std::size_t k = 0;
#if defined(__SSE2__)
    for (; k + 16 <= width; k += 16)
    {
      const __m128i cost = _mm_loadu_si128(reinterpret_cast<const __m128i*>(from + k));
      const __m128i old_cost = _mm_loadu_si128(reinterpret_cast<const __m128i*>(to + k));
      _mm_storeu_si128(reinterpret_cast<__m128i*>(to + k), rule(old_cost, cost));
    }
#endif
    for (; k < width; ++k)
    {
      to[k] = rule(to[k], from[k]);
    }
  }
}
}  // namespace

void mergeMax(const std::uint8_t* layer, std::uint8_t* master, const MergeWindow& window)
{
  mergeRows(layer, master, window, MaxRule{});
}

void mergeOverwrite(const std::uint8_t* layer, std::uint8_t* master, const MergeWindow& window)
{
  mergeRows(layer, master, window, OverwriteRule{});
}
}  // namespace sharing_layer
