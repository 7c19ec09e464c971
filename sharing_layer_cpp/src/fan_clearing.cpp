#include "sharing_layer/fan_clearing.h"

#include <algorithm>
#include <cstddef>

#if defined(__SSE2__) && defined(__x86_64__)
#define SHARING_LAYER_RECIPROCAL_STEPS 1
#include <emmintrin.h>  // (part of every x86-64 target: no runtime dispatch needed)
#endif

namespace sharing_layer
{
namespace
{
/// Lines up to this long along a are stepped by multiplying with the reciprocal of their length (raytraceSse2): the
/// numerators h + s B stay below 2^30, which the reciprocal's precision needs.
constexpr std::uint32_t kMaxReciprocalLength = 16384;
/// ... on grids up to this wide: b * row is one 16-bit multiply (pmaddwd).
constexpr int kMaxReciprocalRow = 32767;

/// Lines longer than this along a are not grouped (no grid holds them: a bound for the arithmetic of closeTo).
constexpr std::uint64_t kMaxRunLength = std::uint64_t{ 1 } << 24;

/// Runs shorter than this are raytraced beam by beam: the fill's per-step work would cost more than it saves.
constexpr std::size_t kMinRun = 3;

/// -1, 0, 1 as line j's slope abs_db / abs_da is below, equal to, above line k's
int compareSlope(const LineSteps& j, const LineSteps& k)
{
  const std::uint64_t l = static_cast<std::uint64_t>(j.abs_db) * k.abs_da;
  const std::uint64_t r = static_cast<std::uint64_t>(k.abs_db) * j.abs_da;
  return (l > r) - (l < r);
}

/// The octant of a line: its dominant axis and the signs along a and b (a b sign of 0, a line along a, goes with +).
int octant(const LineSteps& line)
{
  return (line.x_major ? 4 : 0) + (line.sign_a > 0 ? 2 : 0) + (line.sign_b >= 0 ? 1 : 0);
}

class FanRun
{
public:
  FanRun(std::uint8_t* costs, unsigned int size_x, unsigned int x0, unsigned int y0, std::uint8_t value)
    : costs_(costs), row_(static_cast<int>(size_x)), origin_(static_cast<std::size_t>(y0) * size_x + x0), value_(value)
  {
  }

  FanStats run(const std::vector<LineSteps>& lines)
  {
    run_.clear();
    int run_octant = -1;
    for (const LineSteps& line : lines)
    {
      if (line.end < kNearSteps)
      {
        raytrace(line, 0, line.end);  // too short to share the near field
        continue;
      }
      const int o = octant(line);
      if (o != run_octant || !closeTo(*run_.back(), line))
      {
        flush();
        run_octant = o;
      }
      run_.push_back(&line);
      if (line.end > kNearSteps)
      {
        raytrace(line, kNearSteps + 1, line.end);
      }
    }
    flush();
    return stats_;
  }

private:
  /// Whether beam k's line stays within one cell of the run's last beam j along b over the near steps:
  /// kNearSteps |B_k / A_k - B_j / A_j| + 1 / (2 min(A_j, A_k)) < 1, times 2 A_j A_k.
  static bool closeTo(const LineSteps& j, const LineSteps& k)
  {
    const std::uint64_t aj = j.abs_da, bj = j.abs_db, ak = k.abs_da, bk = k.abs_db;
    if (std::max(aj, ak) > kMaxRunLength)
    {
      return false;  // (the products below stay far inside 64 bits)
    }
    const std::uint64_t cross = bk * aj > bj * ak ? bk * aj - bj * ak : bj * ak - bk * aj;
    return 2 * static_cast<std::uint64_t>(kNearSteps) * cross + std::max(aj, ak) < 2 * aj * ak;
  }

  std::ptrdiff_t stepA(const LineSteps& line) const { return line.x_major ? line.sign_a : line.sign_a * row_; }
  std::ptrdiff_t stepB(const LineSteps& line) const
  {
    const int sign_b = line.sign_b == 0 ? 1 : line.sign_b;  // (no b step is ever taken then)
    return line.x_major ? sign_b * row_ : sign_b;
  }

  /// Steps from .. to of one line, as bresenham2D visits them.
  void raytrace(const LineSteps& line, unsigned int from, unsigned int to)
  {
#if defined(SHARING_LAYER_RECIPROCAL_STEPS)
    if (line.abs_da != 0 && line.abs_da <= kMaxReciprocalLength && row_ <= kMaxReciprocalRow)
    {
      raytraceSse2(line, from, to);
      return;
    }
#endif
    SetCellAction set{ costs_, value_ };
    const std::uint64_t carries = from == 0 ? 0 : line.carries(from);
    const std::uint64_t error = line.abs_da / 2 + static_cast<std::uint64_t>(from) * line.abs_db -
                                carries * line.abs_da;
    const std::size_t cell = origin_ + static_cast<std::size_t>(stepA(line) * static_cast<std::ptrdiff_t>(from)) +
                             static_cast<std::size_t>(stepB(line) * static_cast<std::ptrdiff_t>(carries));
    bresenham2D(set, line.abs_da, line.abs_db, static_cast<int>(error), static_cast<int>(stepA(line)),
                static_cast<int>(stepB(line)), static_cast<std::uint32_t>(cell), to - from);
  }

#if defined(SHARING_LAYER_RECIPROCAL_STEPS)
  /**
   * The same cells, without a branch per step: step s's b is floor(n / A) with n = h + s B, computed as (n M) >> k
   * with M = ceil(2^k / A), k = 31 + floor(log2 A). That is exact: with M A = 2^k + e, 0 <= e < A < 2^(k - 30),
   * and n = q A + r, n M / 2^k = q + (r + n e / 2^k) / A, where n e < 2^30 e < 2^k, so the fraction stays below
   * (r + 1) / A <= 1. n < 2^30 holds for A <= kMaxReciprocalLength (n <= A / 2 + A^2). Four steps per vector,
   * two vectors per pass. Bresenham's carried branch mispredicts on most slopes; on the reference scan's beams
   * this takes about half of bresenham2D's time (-O2). Cell offsets are computed in 32 bits, as bresenham2D takes
   * them. The reciprocal gives each lane's first step and its remainder n mod A; from there a lane carries its
   * remainder, as Bresenham carries its error, but eight steps at a time and without a branch (issue 29: the
   * multiplies were most of the loop's instructions; `bench_core`'s scene at 30 m with obstacle_range 30 m, -O2,
   * raytrace + mark 0.164-0.165 -> 0.144-0.146 ms, as fast as the same arithmetic eight lanes wide with AVX2).
   */
  void raytraceSse2(const LineSteps& line, unsigned int from, unsigned int to)
  {
    const std::uint32_t A = line.abs_da, B = line.abs_db;
    // Locals, not members: a byte store may alias anything, so the members would be loaded again after each write
    // (two loads per cell, half the loop's instructions at -O2).
    std::uint8_t* const costs = costs_;
    const std::uint8_t value = value_;
    const int k = 31 + (31 - __builtin_clz(A));
    const std::uint64_t M = ((std::uint64_t{ 1 } << k) + A - 1) / A;
    const std::uint32_t step_a = static_cast<std::uint32_t>(stepA(line));
    const std::uint32_t b_row = line.x_major ? static_cast<std::uint32_t>(row_) : 1u;
    const bool b_down = line.sign_b < 0;
    std::uint32_t n = A / 2 + from * B;  // (< 2^30, see above)
    std::uint32_t base = static_cast<std::uint32_t>(origin_) + from * step_a;  // the cell at step s, b = 0
    unsigned int left = to - from + 1;
    if (left >= 4)
    {
      const __m128i reciprocal = _mm_set1_epi32(static_cast<int>(static_cast<std::uint32_t>(M)));
      const __m128i shift = _mm_cvtsi32_si128(k);
      const __m128i row = _mm_set1_epi32(static_cast<int>(b_row));  // (< 2^15: pmaddwd's high halves are 0)
      const __m128i length = _mm_set1_epi32(static_cast<int>(A));   // (<= kMaxReciprocalLength < 2^15: the same)
      const auto carries_of = [&](__m128i numerators) {  // four b = floor(n / A), each < 2^15
        const __m128i even = _mm_srl_epi64(_mm_mul_epu32(numerators, reciprocal), shift);
        const __m128i odd = _mm_srl_epi64(_mm_mul_epu32(_mm_srli_epi64(numerators, 32), reciprocal), shift);
        return _mm_or_si128(even, _mm_slli_epi64(odd, 32));
      };
      const auto cells_at = [&](__m128i carries, __m128i bases) {
        const __m128i b_offset = _mm_madd_epi16(carries, row);
        return b_down ? _mm_sub_epi32(bases, b_offset) : _mm_add_epi32(bases, b_offset);
      };
      const auto write = [costs, value](__m128i cells) {
        // (two 64-bit moves out of the vector: storing it and loading the four back cost a fifth more)
        const std::uint64_t low = static_cast<std::uint64_t>(_mm_cvtsi128_si64(cells));
        const std::uint64_t high = static_cast<std::uint64_t>(_mm_cvtsi128_si64(_mm_unpackhi_epi64(cells, cells)));
        costs[static_cast<std::uint32_t>(low)] = value;
        costs[low >> 32] = value;
        costs[static_cast<std::uint32_t>(high)] = value;
        costs[high >> 32] = value;
      };
      const auto lanes = [](std::uint32_t start, std::uint32_t step) {  // four consecutive steps' values
        return _mm_setr_epi32(static_cast<int>(start), static_cast<int>(start + step),
                              static_cast<int>(start + 2 * step), static_cast<int>(start + 3 * step));
      };
      if (left >= 8)
      {
        // Steps s .. s + 3 (first) and s + 4 .. s + 7 (second), each lane with its cell and its remainder
        // (h + s B) mod A, found once by the reciprocal. Eight steps on, a remainder grows by 8 B mod A and a cell by
        // 8 step_a plus 8 B / A steps along b, plus one more where the remainder reaches A: an add, a compare and
        // two masks per lane instead of the reciprocal's two multiplies and three shifts.
        const unsigned int count = left;
        const __m128i first_numerators = lanes(n, B), second_numerators = lanes(n + 4 * B, B);
        const __m128i first_b = carries_of(first_numerators), second_b = carries_of(second_numerators);
        __m128i first = cells_at(first_b, lanes(base, step_a));
        __m128i second = cells_at(second_b, lanes(base + 4 * step_a, step_a));
        __m128i first_rem = _mm_sub_epi32(first_numerators, _mm_madd_epi16(first_b, length));
        __m128i second_rem = _mm_sub_epi32(second_numerators, _mm_madd_epi16(second_b, length));
        const std::uint32_t step_b = b_down ? 0u - b_row : b_row;  // (cells wrap in 32 bits, as above)
        const std::uint32_t carries8 = 8 * B / A;
        const __m128i rem_step = _mm_set1_epi32(static_cast<int>(8 * B - carries8 * A));
        const __m128i cell_step = _mm_set1_epi32(static_cast<int>(8 * step_a + carries8 * step_b));
        const __m128i carry_step = _mm_set1_epi32(static_cast<int>(step_b));
        const __m128i last_rem = _mm_set1_epi32(static_cast<int>(A - 1));  // (remainders < 2 A: signed compare)
        for (;;)
        {
          write(first);
          write(second);
          left -= 8;
          if (left < 8)
          {
            break;
          }
          first_rem = _mm_add_epi32(first_rem, rem_step);
          second_rem = _mm_add_epi32(second_rem, rem_step);
          const __m128i first_carry = _mm_cmpgt_epi32(first_rem, last_rem);
          const __m128i second_carry = _mm_cmpgt_epi32(second_rem, last_rem);
          first_rem = _mm_sub_epi32(first_rem, _mm_and_si128(first_carry, length));
          second_rem = _mm_sub_epi32(second_rem, _mm_and_si128(second_carry, length));
          first = _mm_add_epi32(_mm_add_epi32(first, cell_step), _mm_and_si128(first_carry, carry_step));
          second = _mm_add_epi32(_mm_add_epi32(second, cell_step), _mm_and_si128(second_carry, carry_step));
        }
        n += (count - left) * B;
        base += (count - left) * step_a;
      }
      if (left >= 4)
      {
        write(cells_at(carries_of(lanes(n, B)), lanes(base, step_a)));
        left -= 4;
        n += 4 * B;
        base += 4 * step_a;
      }
    }
    for (; left != 0; --left)
    {
      const std::uint32_t b = static_cast<std::uint32_t>((n * M) >> k);
      costs[b_down ? base - b * b_row : base + b * b_row] = value;
      n += B;
      base += step_a;
    }
  }
#endif

  /// Fills steps 0 .. kNearSteps of the run's beams (their later steps are raytraced already).
  void flush()
  {
    if (run_.empty())
    {
      return;
    }
    if (run_.size() < kMinRun)
    {
      for (const LineSteps* line : run_)
      {
        raytrace(*line, 0, std::min(line->end, kNearSteps));
      }
      run_.clear();
      return;
    }
    ++stats_.groups;
    stats_.grouped_beams += run_.size();
    // At every step b only grows with the slope (see clearFan), so the run covers the b of its least and its
    // greatest slope and every b between.
    std::size_t steepest = 0, flattest = 0;
    for (std::size_t k = 1; k < run_.size(); ++k)
    {
      steepest = compareSlope(*run_[k], *run_[steepest]) > 0 ? k : steepest;
      flattest = compareSlope(*run_[k], *run_[flattest]) < 0 ? k : flattest;
    }
    const LineSteps& top = *run_[steepest];
    const LineSteps& bottom = *run_[flattest];
    const std::ptrdiff_t step_a = stepA(top);  // (the run's lines share their octant)
    const std::ptrdiff_t step_b = stepB(top);
    std::uint32_t top_error = top.abs_da / 2, bottom_error = bottom.abs_da / 2;  // as bresenham2D starts
    std::uint32_t top_b = 0, bottom_b = 0;
    std::size_t column = origin_;  // the cell at step s, b = 0
    std::uint8_t* const costs = costs_;  // (locals: see raytraceSse2)
    const std::uint8_t value = value_;
    for (unsigned int s = 0; s <= kNearSteps; ++s)
    {
      std::size_t cell = column + static_cast<std::size_t>(step_b * static_cast<std::ptrdiff_t>(bottom_b));
      for (std::uint32_t b = bottom_b; b <= top_b; ++b)
      {
        costs[cell] = value;
        cell += static_cast<std::size_t>(step_b);
      }
      stats_.near_cells += top_b - bottom_b + 1;
      column += static_cast<std::size_t>(step_a);
      top_error += top.abs_db;
      if (top_error >= top.abs_da)
      {
        top_error -= top.abs_da;
        ++top_b;
      }
      bottom_error += bottom.abs_db;
      if (bottom_error >= bottom.abs_da)
      {
        bottom_error -= bottom.abs_da;
        ++bottom_b;
      }
    }
    run_.clear();
  }

  std::uint8_t* costs_;
  int row_;
  std::size_t origin_;
  std::uint8_t value_;
  FanStats stats_;
  std::vector<const LineSteps*>& run_ = scratch().run;  ///< the run being gathered, in scan order

  /// Kept from fan to fan (per thread), so that a scan does not allocate them again.
  struct Scratch
  {
    std::vector<const LineSteps*> run;
  };
  static Scratch& scratch()
  {
    thread_local Scratch s;
    return s;
  }
};
}  // namespace

FanStats clearFan(std::uint8_t* costs, unsigned int size_x, unsigned int x0, unsigned int y0,
                  const std::vector<LineSteps>& lines, std::uint8_t value)
{
  return FanRun(costs, size_x, x0, y0, value).run(lines);
}

}  // namespace sharing_layer
