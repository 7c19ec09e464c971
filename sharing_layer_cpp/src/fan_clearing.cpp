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

/// Runs shorter than this are raytraced beam by beam: the fill's per-step work would cost more than it saves (on the
/// reference scan at 3 m and 30 m, -O2, 8 did best of 3, 6, 8, 12 and 16: the beams that end on a pillar close to
/// the sensor make many short runs).
constexpr std::size_t kMinRun = 8;
/// Beams ending before this step are raytraced alone: too short for a fill to save anything.
constexpr unsigned int kMinNearSteps = 8;

/// The steps a near-field fill could cover on this line.
unsigned int nearSteps(const LineSteps& line)
{
  return std::min(line.end, kNearSteps);
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
    for (std::size_t i = 0; i < lines.size(); ++i)
    {
      const LineSteps& line = lines[i];
      // A run fills steps 0 .. its shortest beam's near steps (at most kNearSteps): with raytrace_range 3 m every beam
      // ends before kNearSteps, and its beams overlap as much near the sensor (issue 48). A beam shorter than the run
      // would cut the fill short for the others: in a run that fills all kNearSteps any shorter one, in one that
      // fills fewer one a quarter shorter. Such a beam is raytraced alone when it is one (it ended on something
      // close); when the next is as short, the beams shrink along the octant (those cut at raytrace_range do), and
      // it starts a run of its own, as does one a third longer than the run's.
      const unsigned int near = nearSteps(line);
      const auto shorter = [this](unsigned int steps) {
        return !run_.empty() && steps < run_near_ && (run_near_ == kNearSteps || 4 * steps < 3 * run_near_);
      };
      const bool short_line = shorter(near);
      if (near < kMinNearSteps || (short_line && (i + 1 == lines.size() || !shorter(nearSteps(lines[i + 1])))))
      {
        raytrace(line, 0, line.end);
        continue;
      }
      const int o = octant(line);
      if (o != run_octant || short_line || 3 * near > 4 * run_near_ ||
          !closeTo(*run_.back(), line, std::min(near, nearSteps(*run_.back()))))
      {
        flush();
        run_octant = o;
      }
      run_near_ = run_.empty() ? near : std::min(run_near_, near);
      run_.push_back(&line);
      if (run_near_ == kNearSteps && line.end > kNearSteps)
      {
        // A run that fills kNearSteps keeps them (no shorter beam joins it): the beam's far steps now, while its line
        // is at hand (later, at the flush, the 30 m scan took 3 % longer).
        raytrace(line, kNearSteps + 1, line.end);
      }
    }
    flush();
    return stats_;
  }

private:
  /// Whether beam k's line stays within one cell of the run's last beam j along b over the first `steps` steps:
  /// steps |B_k / A_k - B_j / A_j| + 1 / (2 min(A_j, A_k)) < 1, times 2 A_j A_k. (A run's fill covers no more steps
  /// than its shortest beam's near steps, so the steps of the shorter of two neighbours are enough.)
  static bool closeTo(const LineSteps& j, const LineSteps& k, unsigned int steps)
  {
    const std::uint64_t aj = j.abs_da, bj = j.abs_db, ak = k.abs_da, bk = k.abs_db;
    if (std::max(aj, ak) > kMaxRunLength)
    {
      return false;  // (the products below stay far inside 64 bits)
    }
    const std::uint64_t cross = bk * aj > bj * ak ? bk * aj - bj * ak : bj * ak - bk * aj;
    return 2 * static_cast<std::uint64_t>(steps) * cross + std::max(aj, ak) < 2 * aj * ak;
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

  /// Fills steps 0 .. run_near_ of the run's beams, and raytraces each beam on from there (in a run that fills
  /// kNearSteps, done as each beam joined).
  void flush()
  {
    if (run_.empty())
    {
      return;
    }
    const bool far_done = run_near_ == kNearSteps;  // (their steps beyond kNearSteps were raytraced as they joined)
    if (run_.size() < kMinRun)
    {
      for (const LineSteps* line : run_)
      {
        raytrace(*line, 0, far_done ? std::min(line->end, kNearSteps) : line->end);
      }
      run_.clear();
      return;
    }
    ++stats_.groups;
    stats_.grouped_beams += run_.size();
    // At every step b only grows with the slope (see clearFan), so the run covers the b of its least and its
    // greatest slope and every b between. The slopes are compared exactly (cross-multiplied), the extremes' lengths
    // held in registers: looked up through the last extreme's line, each comparison waited on two loads.
    const LineSteps* top = run_[0];
    const LineSteps* bottom = run_[0];
    std::uint64_t top_da = top->abs_da, top_db = top->abs_db, bottom_da = top_da, bottom_db = top_db;
    for (std::size_t k = 1; k < run_.size(); ++k)
    {
      const LineSteps* line = run_[k];
      const std::uint64_t da = line->abs_da, db = line->abs_db;
      const bool steeper = db * top_da > top_db * da, flatter = db * bottom_da < bottom_db * da;
      top = steeper ? line : top;
      top_da = steeper ? da : top_da;
      top_db = steeper ? db : top_db;
      bottom = flatter ? line : bottom;
      bottom_da = flatter ? da : bottom_da;
      bottom_db = flatter ? db : bottom_db;
    }
    const std::ptrdiff_t step_a = stepA(*top);  // (the run's lines share their octant)
    const std::ptrdiff_t step_b = stepB(*top);
    const std::uint32_t top_a_len = top->abs_da, top_b_len = top->abs_db;
    const std::uint32_t bottom_a_len = bottom->abs_da, bottom_b_len = bottom->abs_db;
    std::uint32_t top_error = top_a_len / 2, bottom_error = bottom_a_len / 2;  // as bresenham2D starts
    std::uint32_t top_b = 0, bottom_b = 0;
    std::size_t column = origin_;  // the cell at step s, b = 0
    std::uint8_t* const costs = costs_;  // (locals: see raytraceSse2)
    const std::uint8_t value = value_;
    const unsigned int near = run_near_;
    std::size_t near_cells = 0;
    for (unsigned int s = 0; s <= near; ++s)
    {
      std::size_t cell = column + static_cast<std::size_t>(step_b * static_cast<std::ptrdiff_t>(bottom_b));
      for (std::uint32_t b = bottom_b; b <= top_b; ++b)
      {
        costs[cell] = value;
        cell += static_cast<std::size_t>(step_b);
      }
      near_cells += top_b - bottom_b + 1;
      column += static_cast<std::size_t>(step_a);
      top_error += top_b_len;
      if (top_error >= top_a_len)
      {
        top_error -= top_a_len;
        ++top_b;
      }
      bottom_error += bottom_b_len;
      if (bottom_error >= bottom_a_len)
      {
        bottom_error -= bottom_a_len;
        ++bottom_b;
      }
    }
    stats_.near_cells += near_cells;
    for (const LineSteps* line : run_)
    {
      if (!far_done && line->end > near)
      {
        raytrace(*line, near + 1, line->end);
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
  unsigned int run_near_ = 0;  ///< the steps its fill covers: the least of its beams' near steps

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
