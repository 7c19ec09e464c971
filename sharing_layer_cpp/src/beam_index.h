#ifndef SHARING_LAYER_SRC_BEAM_INDEX_H
#define SHARING_LAYER_SRC_BEAM_INDEX_H

// Private to applyScan (scan_update.cpp): the index of a scan's beams by direction, for the walk over watched cells.

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>  // (part of every x86-64 target)
#endif

#include "sharing_layer/raytrace.h"

namespace sharing_layer
{
namespace scan_detail
{
/// A monotonic stand-in for atan2(y, x) in [0, 4) (the "diamond angle"): one division instead of atan2.
inline double pseudoAngle(double x, double y)
{
  if (y >= 0.0)
  {
    return x >= 0.0 ? (x + y == 0.0 ? 0.0 : y / (x + y)) : 1.0 - x / (-x + y);
  }
  return x < 0.0 ? 2.0 - y / (-x - y) : 3.0 + x / (x - y);
}

/// The scan's beams as raytraced (endpoint cells after clipping), found by direction from the origin cell so that
/// the beams able to cross a watched region are found without walking every beam. Raytracing only stores each
/// beam's end cell, by point index. The first few regions test every beam against the region's wedge of
/// directions (two cross products, vectorised); later ones test only the beams in buckets of pseudo-angle covering
/// the wedge, sorted once. Beams that end nearer than a region's nearest cell are left out too (most beams towards
/// a far obstacle end on something in front of it). A beam's line is the one raytracing cleared, taken from the
/// caller's list of lines when a region first reaches it.
class BeamIndex
{
public:
  struct Beam
  {
    LineSteps line;
    std::size_t point;         ///< index in the observation
    unsigned int deep_steps;   ///< steps before which a watched cell counts as seen free (kUnset until needed)
    unsigned int own_steps;    ///< the same by the beam's own range only, >= deep_steps (kUnset until needed)
    unsigned int end_x, end_y; ///< end cell
    bool end_is_point;         ///< the end cell holds the point (not clipped to the grid edge)
    std::uint32_t scan;        ///< BeamIndex's stamp of the scan that filled it
  };
  static constexpr unsigned int kUnset = UINT_MAX;
  static constexpr int kBuckets = 1024;      ///< about 0.35 degrees each
  static constexpr std::size_t kLinearQueries = 2;  ///< regions answered by testing every beam before buckets pay off

  /// For an observation of `points` points, raytraced from cell (x0, y0) along `lines` (filled by the caller as it
  /// adds the beams), to be asked about `queries` regions: beyond kLinearQueries, the buckets are built for the first.
  BeamIndex(std::size_t points, unsigned int x0, unsigned int y0, const std::vector<LineSteps>& lines,
            std::size_t queries)
    : x0_(x0)
    , y0_(y0)
    , lines_(lines)
    , n_(static_cast<std::uint32_t>(points))
    , s_(storage())
    , queries_(queries > kLinearQueries ? kLinearQueries : 0)
  {
    if (s_.dx.size() < points)
    {
      s_.end_x.resize(points);
      s_.end_y.resize(points);
      s_.line_of.resize(points);
      s_.dx.resize(points);
      s_.dy.resize(points);
      s_.pass.resize(points);
    }
    s_.state.assign(points, kNone);
    end_x_ = s_.end_x.data();
    end_y_ = s_.end_y.data();
    dx_ = s_.dx.data();
    dy_ = s_.dy.data();
    state_ = s_.state.data();
  }

  /// The beam of point `point` ends in cell (x1, y1) and was raytraced along lines[line]; clipped: the point lies off
  /// the grid, (x1, y1) on its edge.
  void add(std::size_t point, unsigned int x1, unsigned int y1, bool clipped, std::size_t line)
  {
    end_x_[point] = x1;  // (raytracing's inner loop: as little as possible here)
    end_y_[point] = y1;
    s_.line_of[point] = static_cast<std::uint32_t>(line);
    state_[point] = clipped ? kClipped : kEndsInPoint;
  }

  /// Calls f(beam) for every beam that can visit a cell of [min_x, max_x] x [min_y, max_y]: its direction lies
  /// within the directions of the rectangle's corners grown by the slack of a Bresenham line, and its end cell is
  /// not nearer than the rectangle. No add after the first call.
  template <class F>
  void forEachTowards(int min_x, int min_y, int max_x, int max_y, F f)
  {
    if (!prepared_)
    {
      prepare();
    }
    // A beam visits a cell only where the exact line between the start and end cells' centres passes within
    // half a cell of the cell's centre along b (Bresenham rounds b to the nearest cell), so only through the
    // cell's own square: its corners bound the directions, with a margin for rounding.
    constexpr double kGrow = 0.5 + 0.05;
    const double x_lo = min_x - static_cast<double>(x0_) - kGrow, x_hi = max_x - static_cast<double>(x0_) + kGrow;
    const double y_lo = min_y - static_cast<double>(y0_) - kGrow, y_hi = max_y - static_cast<double>(y0_) + kGrow;
    // The cells a beam visits lie within half a cell beyond its end cell's distance from the origin cell (step i
    // is i cells along a and within half a cell of the exact line along b).
    const double near_x = std::max(0.0, std::max(min_x - static_cast<double>(x0_), static_cast<double>(x0_) - max_x));
    const double near_y = std::max(0.0, std::max(min_y - static_cast<double>(y0_), static_cast<double>(y0_) - max_y));
    // (near - 0.5)^2 >= near^2 - (near_x + near_y), as near <= near_x + near_y: a bound without a square root.
    const double reach_sq = near_x * near_x + near_y * near_y - (near_x + near_y);
    Wedge w;
    // Single precision, so that testing every beam vectorises; the thresholds are loosened far beyond its rounding
    // (a beam let through in excess is walked to no effect).
    w.reach_sq = reach_sq > 0.0 ? static_cast<float>(reach_sq * (1.0 - 1e-5)) : -1.0f;
    const bool around_origin = x_lo <= 0.5 && x_hi >= -0.5 && y_lo <= 0.5 && y_hi >= -0.5;
    const double corners[4][2] = { { x_lo, y_lo }, { x_hi, y_lo }, { x_lo, y_hi }, { x_hi, y_hi } };
    int first = 0, last = 0;
    if (!around_origin)  // (around it, the zero wedge admits every direction)
    {
      // The rectangle does not hold the origin, so its directions span less than half a turn: the clockwise-most
      // and counter-clockwise-most corners bound them, and a beam lies between them when both cross products
      // are >= 0.
      const auto cross = [](double ax, double ay, double bx, double by) { return ax * by - ay * bx; };
      for (int j = 1; j < 4; ++j)
      {
        if (cross(corners[first][0], corners[first][1], corners[j][0], corners[j][1]) < 0.0)
        {
          first = j;
        }
        if (cross(corners[last][0], corners[last][1], corners[j][0], corners[j][1]) > 0.0)
        {
          last = j;
        }
      }
      w.first_x = static_cast<float>(corners[first][0]);
      w.first_y = static_cast<float>(corners[first][1]);
      w.last_x = static_cast<float>(corners[last][0]);
      w.last_y = static_cast<float>(corners[last][1]);
    }
    const float* dx = dx_;
    const float* dy = dy_;
    const std::uint8_t* state = state_;
    if (queries_ < kLinearQueries)  // test every beam
    {
      ++queries_;
      std::uint8_t* pass = s_.pass.data();
      const std::uint32_t n = n_;  // a local: the byte stores below could alias a member
      for (std::uint32_t i = 0; i < n; ++i)  // (a point without a beam holds an old direction: state says so)
      {
        pass[i] = (state[i] != kNone) & w.admits(dx[i], dy[i]);
      }
      for (std::uint32_t i = 0; i < n; ++i)
      {
        if (pass[i])
        {
          visitBeam(i, f);
        }
      }
      return;
    }
    if (!bucketed_)
    {
      buildBuckets();
    }
    // The beams of a run of buckets lie side by side in sorted order: tested together (vectorised), then visited.
    const auto visit_range = [&](double lo, double hi) {
      const std::uint32_t from = s_.start[bucketOf(lo)], to = s_.start[bucketOf(hi) + 1];
      const float* sorted_dx = s_.sorted_dx.data();
      const float* sorted_dy = s_.sorted_dy.data();
      std::uint8_t* pass = s_.pass.data();
      for (std::uint32_t k = from; k < to; ++k)
      {
        pass[k] = w.admits(sorted_dx[k], sorted_dy[k]);
      }
      for (std::uint32_t k = from; k < to; ++k)
      {
        if (pass[k])
        {
          visitBeam(s_.order[k], f);
        }
      }
    };
    if (around_origin)
    {
      visit_range(0.0, 4.0);
      return;
    }
    // The wedge runs counter-clockwise from the first corner's direction to the last's.
    const double lo = pseudoAngle(corners[first][0], corners[first][1]);
    const double hi = pseudoAngle(corners[last][0], corners[last][1]);
    if (lo > hi)  // straddles the +x axis (0 / 4): two intervals
    {
      visit_range(lo, 4.0);
      visit_range(0.0, hi);
      return;
    }
    visit_range(lo, hi);
  }

private:
  static constexpr std::uint8_t kNone = 0;        ///< the point made no beam (unusable, or no clearing)
  static constexpr std::uint8_t kEndsInPoint = 1;
  static constexpr std::uint8_t kClipped = 2;

  /// Directions between first and last (counter-clockwise; all zero: every direction), and a least squared length.
  struct Wedge
  {
    float first_x = 0.0f, first_y = 0.0f, last_x = 0.0f, last_y = 0.0f;
    float reach_sq = -1.0f;
    bool admits(float x, float y) const
    {
      return (first_x * y - first_y * x >= 0.0f) & (x * last_y - y * last_x >= 0.0f) & (x * x + y * y >= reach_sq);
    }
  };

  static int bucketOf(double angle)
  {
    return std::min(kBuckets - 1, std::max(0, static_cast<int>(angle * (kBuckets / 4.0))));
  }

  void prepare()
  {
    if (s_.beams.size() < n_)
    {
      s_.beams.resize(n_);  // a beam is filled when first reached in a scan
    }
    // Directions in single precision, which holds any cell offset of a grid below 2^24 cells a side exactly.
    const std::uint32_t n = n_;
    const std::uint32_t* end_x = end_x_;
    const std::uint32_t* end_y = end_y_;
    float* dx = dx_;
    float* dy = dy_;
    const float x0 = static_cast<float>(x0_), y0 = static_cast<float>(y0_);
    for (std::uint32_t i = 0; i < n; ++i)
    {
      dx[i] = static_cast<float>(static_cast<std::int32_t>(end_x[i])) - x0;
      dy[i] = static_cast<float>(static_cast<std::int32_t>(end_y[i])) - y0;
    }
    if (++s_.scan == 0)  // wrapped: stamps of old scans could match again
    {
      for (Beam& beam : s_.beams)
      {
        beam.scan = 0;
      }
      s_.scan = 1;
    }
    prepared_ = true;
  }

  /// Counting sort by the bucket of each beam's pseudo-angle into order; afterwards bucket b holds
  /// order[start[b] .. start[b + 1]).
  void buildBuckets()
  {
    s_.start.assign(kBuckets + 2, 0);
    s_.bucket_of.resize(n_);
    const float* dx = s_.dx.data();
    const float* dy = s_.dy.data();
    std::uint16_t* bucket_of = s_.bucket_of.data();
    const std::uint32_t n = n_;
    std::uint32_t i = 0;
#if defined(__SSE2__)
    // The loop below, four beams per vector: GCC vectorises it at -O3 but not at -O2 (its "very cheap" cost model
    // refuses loops that need a scalar epilogue), where it was a third of the walk's fixed cost per scan (issue 29).
    // The same operations in the same order, so the same buckets.
    {
      const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
      const __m128 tiny = _mm_set1_ps(1e-30f), zero = _mm_setzero_ps(), two = _mm_set1_ps(2.0f);
      const __m128 four = _mm_set1_ps(4.0f), scale = _mm_set1_ps(kBuckets / 4.0f);
      const __m128 top = _mm_set1_ps(static_cast<float>(kBuckets - 1));
      for (; i + 4 <= n; i += 4)
      {
        const __m128 x = _mm_loadu_ps(dx + i), y = _mm_loadu_ps(dy + i);
        const __m128 sum = _mm_max_ps(_mm_add_ps(_mm_and_ps(x, abs_mask), _mm_and_ps(y, abs_mask)), tiny);
        const __m128 p = _mm_div_ps(y, sum);
        const __m128 right = _mm_cmpge_ps(x, zero);
        const __m128 right_angle = _mm_add_ps(p, _mm_and_ps(_mm_cmplt_ps(p, zero), four));
        const __m128 angle = _mm_or_ps(_mm_and_ps(right, right_angle), _mm_andnot_ps(right, _mm_sub_ps(two, p)));
        // (min first, as below: a NaN would go to the top bucket either way)
        const __m128 bucket = _mm_max_ps(_mm_min_ps(_mm_mul_ps(angle, scale), top), zero);
        const __m128i whole = _mm_cvttps_epi32(bucket);
        _mm_storel_epi64(reinterpret_cast<__m128i*>(bucket_of + i), _mm_packs_epi32(whole, whole));
      }
    }
#endif
    for (; i < n; ++i)  // pseudoAngle without branches
    {
      const float sum = std::max(std::fabs(dx[i]) + std::fabs(dy[i]), 1e-30f);
      const float p = dy[i] / sum;  // [-1, 1]
      // x >= 0: p, or 4 + p below the axis; x < 0: 2 - p (pseudoAngle's four quadrants)
      const float right = static_cast<float>(dx[i] >= 0.0f), below = static_cast<float>(p < 0.0f);
      const float angle = right * (p + 4.0f * below) + (1.0f - right) * (2.0f - p);
      // (a point without a beam lands in some bucket, and is never admitted)
      bucket_of[i] = static_cast<std::uint16_t>(
          std::max(0.0f, std::min(static_cast<float>(kBuckets - 1), angle * (kBuckets / 4.0f))));
    }
    for (std::uint32_t i = 0; i < n; ++i)
    {
      ++s_.start[bucket_of[i] + 2];
    }
    for (int b = 2; b < kBuckets + 2; ++b)
    {
      s_.start[b] += s_.start[b - 1];
    }
    // Bucket b's entries are placed from start[b + 1] on, which then ends where bucket b + 1 begins. Points
    // without a beam get a NaN direction, which no wedge admits.
    s_.order.resize(n);
    s_.sorted_dx.resize(n);
    s_.sorted_dy.resize(n);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (std::uint32_t i = 0; i < n; ++i)
    {
      const std::uint32_t k = s_.start[bucket_of[i] + 1]++;
      s_.order[k] = i;
      s_.sorted_dx[k] = state_[i] != kNone ? dx[i] : nan;
      s_.sorted_dy[k] = state_[i] != kNone ? dy[i] : nan;
    }
    bucketed_ = true;
  }

  template <class F>
  void visitBeam(std::uint32_t i, F& f)
  {
    Beam& beam = s_.beams[i];
    if (beam.scan != s_.scan)
    {
      beam.scan = s_.scan;
      beam.end_x = end_x_[i];
      beam.end_y = end_y_[i];
      beam.line = lines_[s_.line_of[i]];
      beam.point = i;
      beam.deep_steps = kUnset;
      beam.own_steps = kUnset;
      beam.end_is_point = state_[i] == kEndsInPoint;
    }
    f(beam);
  }

  /// Buffers kept from scan to scan, one set per thread: once grown, a scan allocates nothing for its beams.
  struct Storage
  {
    std::vector<std::uint8_t> state;         ///< per point: kNone, kEndsInPoint or kClipped
    std::vector<std::uint32_t> end_x, end_y;  ///< per point with a beam: its end cell
    std::vector<std::uint32_t> line_of;       ///< per point with a beam: its line in lines_
    std::vector<float> dx, dy;               ///< the same minus the origin cell (filled when first asked)
    std::vector<std::uint8_t> pass;          ///< wedge test of every beam
    std::vector<Beam> beams;
    std::uint32_t scan = 0;  ///< stamp of the current scan: a beam with another stamp is not filled yet
    std::vector<std::uint16_t> bucket_of;
    std::vector<std::uint32_t> start;  ///< see buildBuckets
    std::vector<std::uint32_t> order;  ///< beam indexes by bucket
    std::vector<float> sorted_dx, sorted_dy;  ///< their directions in that order
  };
  static Storage& storage()
  {
    thread_local Storage storage;
    return storage;
  }

  unsigned int x0_, y0_;
  const std::vector<LineSteps>& lines_;
  std::uint32_t n_;
  Storage& s_;
  std::uint32_t* end_x_;
  std::uint32_t* end_y_;
  float* dx_;
  float* dy_;
  std::uint8_t* state_;
  bool prepared_ = false;
  bool bucketed_ = false;
  std::size_t queries_;  ///< answered so far (starts at kLinearQueries when buckets pay off from the first)
};
}  // namespace scan_detail
}  // namespace sharing_layer

#endif  // SHARING_LAYER_SRC_BEAM_INDEX_H
