#include "fleet_nav/inflation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace fleet_nav
{
namespace
{
constexpr std::uint8_t kLethal = 254;
constexpr std::uint8_t kInscribed = 253;
constexpr std::uint8_t kUnknown = 255;
constexpr double kFar = 1e20;

std::string num(double v)
{
  return std::to_string(v);
}

// Felzenszwalb–Huttenlocher 1-D squared distance transform of f (n samples) into d.
void transform1d(const double* f, int n, double* d, int* v, double* z)
{
  int k = 0;
  v[0] = 0;
  z[0] = -kFar;
  z[1] = kFar;
  for (int q = 1; q < n; ++q)
  {
    double s = ((f[q] + double(q) * q) - (f[v[k]] + double(v[k]) * v[k])) / (2.0 * q - 2.0 * v[k]);
    while (s <= z[k])
    {
      --k;
      s = ((f[q] + double(q) * q) - (f[v[k]] + double(v[k]) * v[k])) / (2.0 * q - 2.0 * v[k]);
    }
    ++k;
    v[k] = q;
    z[k] = s;
    z[k + 1] = kFar;
  }
  k = 0;
  for (int q = 0; q < n; ++q)
  {
    while (z[k + 1] < q)
    {
      ++k;
    }
    const double dq = q - v[k];
    d[q] = dq * dq + f[v[k]];
  }
}
}  // namespace

void InflationParams::validate() const
{
  if (!(resolution > 0.0) || !std::isfinite(resolution))
  {
    throw std::invalid_argument("resolution must be > 0, got " + num(resolution));
  }
  if (!(inscribed_radius >= 0.0) || !std::isfinite(inscribed_radius))
  {
    throw std::invalid_argument("inscribed_radius must be >= 0, got " + num(inscribed_radius));
  }
  if (!(inflation_radius >= 0.0) || !std::isfinite(inflation_radius))
  {
    throw std::invalid_argument("inflation_radius must be >= 0, got " + num(inflation_radius));
  }
  if (inflation_radius / resolution > 2000.0)
  {
    throw std::invalid_argument("inflation_radius " + num(inflation_radius) + " m is over 2000 cells at " +
                                num(resolution) + " m/cell");
  }
  if (!(cost_scaling_factor >= 0.0) || !std::isfinite(cost_scaling_factor))
  {
    throw std::invalid_argument("cost_scaling_factor must be >= 0, got " + num(cost_scaling_factor));
  }
}

Inflator::Inflator(const InflationParams& params) : params_(params)
{
  params_.validate();
  // costmap_2d's cellDistance: ceil(world / resolution).
  cell_radius_ = static_cast<unsigned int>(std::max(0.0, std::ceil(params_.inflation_radius / params_.resolution)));
  const std::size_t max_sq = static_cast<std::size_t>(cell_radius_) * cell_radius_;
  cost_by_sq_distance_.resize(max_sq + 1);
  for (std::size_t s = 0; s <= max_sq; ++s)
  {
    cost_by_sq_distance_[s] = costAtDistance(std::sqrt(static_cast<double>(s)));
  }
}

std::uint8_t Inflator::costAtDistance(double distance_cells) const
{
  if (distance_cells == 0.0)
  {
    return kLethal;
  }
  if (distance_cells > cell_radius_)
  {
    return 0;
  }
  const double metres = distance_cells * params_.resolution;
  if (metres <= params_.inscribed_radius)
  {
    return kInscribed;
  }
  const double factor = std::exp(-params_.cost_scaling_factor * (metres - params_.inscribed_radius));
  return static_cast<std::uint8_t>((kInscribed - 1) * factor);
}

void Inflator::inflate(const std::uint8_t* master, unsigned int size_x, unsigned int size_y, std::uint8_t* out,
                       unsigned int min_x, unsigned int min_y, unsigned int max_x, unsigned int max_y)
{
  if (master == nullptr || out == nullptr)
  {
    throw std::invalid_argument("Inflator::inflate: null grid");
  }
  if (size_x == 0 || size_y == 0)
  {
    throw std::invalid_argument("Inflator::inflate: empty grid");
  }
  max_x = std::min(max_x, size_x);
  max_y = std::min(max_y, size_y);
  if (min_x >= max_x || min_y >= max_y)
  {
    return;
  }
  const unsigned int r = cell_radius_;
  const unsigned int px0 = min_x > r ? min_x - r : 0;
  const unsigned int py0 = min_y > r ? min_y - r : 0;
  const unsigned int px1 = std::min(size_x, max_x + r);
  const unsigned int py1 = std::min(size_y, max_y + r);
  const int w = static_cast<int>(px1 - px0);
  const int h = static_cast<int>(py1 - py0);
  const int longest = std::max(w, h);
  dist_.assign(static_cast<std::size_t>(w) * h, kFar);
  f_.resize(longest);
  d_.resize(longest);
  v_.resize(longest);
  z_.resize(longest + 1);

  for (int y = 0; y < h; ++y)
  {
    const std::uint8_t* row = master + static_cast<std::size_t>(py0 + y) * size_x + px0;
    double* drow = dist_.data() + static_cast<std::size_t>(y) * w;
    for (int x = 0; x < w; ++x)
    {
      if (row[x] == kLethal)
      {
        drow[x] = 0.0;
      }
    }
  }
  // Columns, then rows.
  for (int x = 0; x < w; ++x)
  {
    for (int y = 0; y < h; ++y)
    {
      f_[y] = dist_[static_cast<std::size_t>(y) * w + x];
    }
    transform1d(f_.data(), h, d_.data(), v_.data(), z_.data());
    for (int y = 0; y < h; ++y)
    {
      dist_[static_cast<std::size_t>(y) * w + x] = d_[y];
    }
  }
  const double max_sq = static_cast<double>(cost_by_sq_distance_.size() - 1);
  for (unsigned int y = min_y; y < max_y; ++y)
  {
    double* drow = dist_.data() + static_cast<std::size_t>(y - py0) * w;
    std::copy(drow, drow + w, f_.begin());
    transform1d(f_.data(), w, d_.data(), v_.data(), z_.data());
    const std::uint8_t* in = master + static_cast<std::size_t>(y) * size_x;
    std::uint8_t* o = out + static_cast<std::size_t>(y) * size_x;
    for (unsigned int x = min_x; x < max_x; ++x)
    {
      const double sq = d_[x - px0];
      const std::uint8_t cost = sq > max_sq ? 0 : cost_by_sq_distance_[static_cast<std::size_t>(sq)];
      const std::uint8_t old = in[x];
      if (old == kUnknown)
      {
        o[x] = cost >= kInscribed ? cost : kUnknown;
      }
      else
      {
        o[x] = std::max(old, cost);
      }
    }
  }
}

}  // namespace fleet_nav
