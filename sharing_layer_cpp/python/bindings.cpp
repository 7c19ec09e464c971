// pybind11 module over the ROS-free core. Cell lists and grids cross as NumPy arrays,
// copied with memcpy or shared without copy, so no hot path runs a Python loop per cell.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "sharing_layer/cost_values.h"
#include "sharing_layer/raycast.h"
#include "sharing_layer/raytrace.h"
#include "sharing_layer/scan_update.h"
#include "sharing_layer/sharing_core.h"

namespace py = pybind11;
using namespace sharing_layer;

namespace sharing_layer
{
void bindFleetRobots(py::module& m);  // bind_fleet_robots.cpp
}

namespace
{
using IndexArray = py::array_t<std::uint32_t, py::array::c_style | py::array::forcecast>;
using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

py::array_t<std::uint32_t> toArray(const std::vector<std::uint32_t>& cells)
{
  py::array_t<std::uint32_t> out(static_cast<py::ssize_t>(cells.size()));
  if (!cells.empty())
  {
    std::memcpy(out.mutable_data(), cells.data(), cells.size() * sizeof(std::uint32_t));
  }
  return out;
}

std::vector<std::uint32_t> toCells(const py::object& obj, const char* what)
{
  // Negative or fractional values must not wrap silently into valid indexes.
  py::array arr = py::array::ensure(obj);
  if (!arr)
  {
    throw py::value_error(std::string(what) + ": expected an array of cell indexes");
  }
  if (arr.ndim() > 1)
  {
    throw py::value_error(std::string(what) + ": expected a 1-D array, got " + std::to_string(arr.ndim()) + " dims");
  }
  if (arr.size() == 0)
  {
    return {};
  }
  const char kind = arr.dtype().kind();
  if (kind != 'u' && kind != 'i')
  {
    throw py::value_error(std::string(what) + ": cell indexes must be integers, got dtype kind '" + kind + "'");
  }
  auto as_int = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(arr);
  const std::int64_t* data = as_int.data();
  std::vector<std::uint32_t> cells(static_cast<std::size_t>(as_int.size()));
  for (std::size_t i = 0; i < cells.size(); ++i)
  {
    if (data[i] < 0 || data[i] > 0xFFFFFFFFll)
    {
      throw py::value_error(std::string(what) + ": cell index " + std::to_string(data[i]) + " out of range");
    }
    cells[i] = static_cast<std::uint32_t>(data[i]);
  }
  return cells;
}

Observation toObservation(const std::tuple<double, double, double>& origin, const DoubleArray& points)
{
  if (points.size() != 0 && (points.ndim() != 2 || points.shape(1) != 3))
  {
    throw py::value_error("points must be an (N, 3) array of x, y, z; got shape with " +
                          std::to_string(points.ndim()) + " dims");
  }
  Observation obs;
  obs.origin = Point3{ std::get<0>(origin), std::get<1>(origin), std::get<2>(origin) };
  const std::size_t n = points.size() == 0 ? 0 : static_cast<std::size_t>(points.shape(0));
  obs.points.resize(n);
  static_assert(sizeof(Point3) == 3 * sizeof(double), "Point3 must be three packed doubles");
  if (n > 0)
  {
    std::memcpy(static_cast<void*>(obs.points.data()), points.data(), n * sizeof(Point3));
  }
  return obs;
}

py::array_t<double> scanToPoints(const DoubleArray& ranges, double angle_min, double angle_increment,
                                 double range_min, double range_max, double sensor_x, double sensor_y,
                                 double sensor_yaw, double sensor_z)
{
  if (!std::isfinite(angle_min) || !std::isfinite(angle_increment) || !std::isfinite(sensor_x) ||
      !std::isfinite(sensor_y) || !std::isfinite(sensor_yaw) || !std::isfinite(sensor_z))
  {
    throw py::value_error("scan_to_points: angles and sensor pose must be finite");
  }
  if (!(range_min >= 0.0) || !(range_max > range_min) || !std::isfinite(range_max))
  {
    throw py::value_error("scan_to_points: need 0 <= range_min < range_max (finite), got " +
                          std::to_string(range_min) + ", " + std::to_string(range_max));
  }
  const py::ssize_t n = ranges.size();
  std::vector<double> out;
  out.reserve(static_cast<std::size_t>(n) * 3);
  const double* r = ranges.data();
  // laser_geometry's projection: readings outside [range_min, range_max) are not points.
  for (py::ssize_t i = 0; i < n; ++i)
  {
    if (!(r[i] >= range_min) || !(r[i] < range_max))
    {
      continue;
    }
    const double a = sensor_yaw + angle_min + angle_increment * static_cast<double>(i);
    out.push_back(sensor_x + r[i] * std::cos(a));
    out.push_back(sensor_y + r[i] * std::sin(a));
    out.push_back(sensor_z);
  }
  py::array_t<double> arr({ static_cast<py::ssize_t>(out.size() / 3), static_cast<py::ssize_t>(3) });
  if (!out.empty())
  {
    std::memcpy(arr.mutable_data(), out.data(), out.size() * sizeof(double));
  }
  return arr;
}

Subsection toSubsection(const std::vector<double>& values)
{
  if (values.size() != 4)
  {
    throw py::value_error("rectangle must have 4 values [min_x, min_y, max_x, max_y], got " +
                          std::to_string(values.size()));
  }
  return Subsection(values[0], values[1], values[2], values[3]);
}
}  // namespace

PYBIND11_MODULE(_sharing_core, m)
{
  m.doc() = "ROS-free core of the fleet obstacle-sharing layer";
  m.attr("FREE_SPACE") = FREE_SPACE;
  m.attr("LETHAL_OBSTACLE") = LETHAL_OBSTACLE;
  m.attr("INSCRIBED_INFLATED_OBSTACLE") = INSCRIBED_INFLATED_OBSTACLE;
  m.attr("NO_INFORMATION") = NO_INFORMATION;

  py::register_exception_translator([](std::exception_ptr p) {
    try
    {
      if (p)
      {
        std::rethrow_exception(p);
      }
    }
    catch (const std::invalid_argument& e)
    {
      PyErr_SetString(PyExc_ValueError, e.what());
    }
  });

  py::class_<GridGeometry>(m, "GridGeometry", "Placement and size of a grid (costmap_2d conventions)")
      .def(py::init<double, double, double, unsigned int, unsigned int>(), py::arg("resolution"),
           py::arg("origin_x"), py::arg("origin_y"), py::arg("size_x"), py::arg("size_y"))
      .def_readonly("resolution", &GridGeometry::resolution)
      .def_readonly("origin_x", &GridGeometry::origin_x)
      .def_readonly("origin_y", &GridGeometry::origin_y)
      .def_readonly("size_x", &GridGeometry::size_x)
      .def_readonly("size_y", &GridGeometry::size_y)
      .def("world_to_map",
           [](const GridGeometry& g, double wx, double wy) -> py::object {
             unsigned int mx = 0, my = 0;
             if (!g.worldToMap(wx, wy, mx, my))
             {
               return py::none();
             }
             return py::make_tuple(mx, my);
           },
           "Cell (mx, my) of a world point, or None outside the grid")
      .def("map_to_world",
           [](const GridGeometry& g, unsigned int mx, unsigned int my) {
             double wx = 0.0, wy = 0.0;
             g.mapToWorld(mx, my, wx, wy);
             return py::make_tuple(wx, wy);
           })
      .def("same_as", &GridGeometry::sameAs)
      .def("cell_count", &GridGeometry::cellCount)
      .def("__repr__", [](const GridGeometry& g) { return "GridGeometry(" + g.describe() + ")"; });

  m.def("raytrace_line",
        [](unsigned int x0, unsigned int y0, unsigned int x1, unsigned int y1, unsigned int size_x,
           unsigned int size_y, unsigned int max_length) {
          if (x0 >= size_x || x1 >= size_x || y0 >= size_y || y1 >= size_y)
          {
            throw py::value_error("raytrace_line: both ends must lie inside the " + std::to_string(size_x) + "x" +
                                  std::to_string(size_y) + " grid");
          }
          std::vector<std::uint32_t> cells;
          CollectAction<std::vector<std::uint32_t>> collect{ &cells };
          raytraceLine(collect, x0, y0, x1, y1, size_x, max_length);
          return toArray(cells);
        },
        py::arg("x0"), py::arg("y0"), py::arg("x1"), py::arg("y1"), py::arg("size_x"), py::arg("size_y"),
        py::arg("max_length") = 0xFFFFFFFFu,
        "Flat indexes visited by costmap_2d's raytraceLine from (x0, y0) to (x1, y1), in order");

  m.def("raycast_ranges",
        [](py::array_t<std::uint8_t, py::array::c_style | py::array::forcecast> grid, double resolution,
           double origin_x, double origin_y, double sensor_x, double sensor_y, const DoubleArray& angles,
           double min_range, double max_range) {
          if (grid.ndim() != 2)
          {
            throw py::value_error("raycast_ranges: grid must be 2-D (size_y, size_x)");
          }
          const GridGeometry g(resolution, origin_x, origin_y, static_cast<unsigned int>(grid.shape(1)),
                               static_cast<unsigned int>(grid.shape(0)));
          py::array_t<float> ranges(angles.size());
          {
            py::gil_scoped_release release;
            raycastRanges(g, grid.data(), static_cast<std::size_t>(grid.size()), sensor_x, sensor_y, angles.data(),
                          static_cast<std::size_t>(angles.size()), min_range, max_range, ranges.mutable_data());
          }
          return ranges;
        },
        py::arg("grid"), py::arg("resolution"), py::arg("origin_x"), py::arg("origin_y"), py::arg("sensor_x"),
        py::arg("sensor_y"), py::arg("angles"), py::arg("min_range"), py::arg("max_range"),
        "Simulated ranges: distance to the first non-zero cell along each absolute angle (float32)");

  m.def("scan_to_points", &scanToPoints, py::arg("ranges"), py::arg("angle_min"), py::arg("angle_increment"),
        py::arg("range_min"), py::arg("range_max"), py::arg("sensor_x"), py::arg("sensor_y"), py::arg("sensor_yaw"),
        py::arg("sensor_z") = 0.0,
        "Projects a LaserScan into (N, 3) world points; readings outside [range_min, range_max) are dropped");

  py::class_<ScanLimits>(m, "ScanLimits")
      .def(py::init([](double obstacle_range, double raytrace_range, double min_h, double max_h) {
             ScanLimits l;
             l.obstacle_range = obstacle_range;
             l.raytrace_range = raytrace_range;
             l.min_obstacle_height = min_h;
             l.max_obstacle_height = max_h;
             l.validate();
             return l;
           }),
           py::arg("obstacle_range") = 2.5, py::arg("raytrace_range") = 3.0, py::arg("min_obstacle_height") = 0.0,
           py::arg("max_obstacle_height") = 2.0)
      .def_readonly("obstacle_range", &ScanLimits::obstacle_range)
      .def_readonly("raytrace_range", &ScanLimits::raytrace_range)
      .def_readonly("min_obstacle_height", &ScanLimits::min_obstacle_height)
      .def_readonly("max_obstacle_height", &ScanLimits::max_obstacle_height);

  py::class_<LayerParams>(m, "LayerParams", "Sharing-layer parameters; validated on construction")
      .def(py::init([](double obstacle_range, double raytrace_range, double min_h, double max_h, int static_tolerance,
                       int static_occupied_cost, const std::string& strategy, double trigger_debounce,
                       unsigned int cluster_gap, std::size_t min_cluster_cells, double rectangle_padding,
                       std::size_t max_update_cells, const std::string& robot_name, double clearing_margin,
                       unsigned int clearing_scans, double clearing_time, unsigned int clearing_neighbours,
                       double trigger_memory, double trigger_radius, double inscribed_radius,
                       bool memory_on_stuck_feedback, double lease_renewal_interval) {
             if (static_occupied_cost < 1 || static_occupied_cost > 255)
             {
               throw py::value_error("static_occupied_cost must be 1..255, got " +
                                     std::to_string(static_occupied_cost));
             }
             LayerParams p;
             p.limits.obstacle_range = obstacle_range;
             p.limits.raytrace_range = raytrace_range;
             p.limits.min_obstacle_height = min_h;
             p.limits.max_obstacle_height = max_h;
             p.static_tolerance = static_tolerance;
             p.static_occupied_cost = static_cast<std::uint8_t>(static_occupied_cost);
             p.strategy = parseProposalStrategy(strategy);
             p.trigger_debounce = trigger_debounce;
             p.cluster_gap = cluster_gap;
             p.min_cluster_cells = min_cluster_cells;
             p.rectangle_padding = rectangle_padding;
             p.max_update_cells = max_update_cells;
             p.robot_name = robot_name;
             p.clearing_margin = clearing_margin;
             p.clearing_scans = clearing_scans;
             p.clearing_time = clearing_time;
             p.clearing_neighbours = clearing_neighbours;
             p.trigger_memory = trigger_memory;
             p.trigger_radius = trigger_radius;
             p.inscribed_radius = inscribed_radius;
             p.memory_on_stuck_feedback = memory_on_stuck_feedback;
             p.lease_renewal_interval = lease_renewal_interval;
             p.validate();
             return p;
           }),
           py::arg("obstacle_range") = 2.5, py::arg("raytrace_range") = 3.0, py::arg("min_obstacle_height") = 0.0,
           py::arg("max_obstacle_height") = 2.0, py::arg("static_tolerance") = 3,
           py::arg("static_occupied_cost") = 254, py::arg("proposal_strategy") = "sectors",
           py::arg("trigger_debounce") = 2.0, py::arg("cluster_gap") = 1, py::arg("min_cluster_cells") = 1,
           py::arg("rectangle_padding") = 0.0, py::arg("max_update_cells") = 1000000,
           py::arg("robot_name") = "robot", py::arg("clearing_margin") = 0.1, py::arg("clearing_scans") = 3,
           py::arg("clearing_time") = 1.0, py::arg("clearing_neighbours") = 8, py::arg("trigger_memory") = 30.0,
           py::arg("trigger_radius") = 4.0, py::arg("inscribed_radius") = 0.25,
           py::arg("memory_on_stuck_feedback") = false, py::arg("lease_renewal_interval") = 5.0)
      .def_property_readonly("obstacle_range", [](const LayerParams& p) { return p.limits.obstacle_range; })
      .def_property_readonly("raytrace_range", [](const LayerParams& p) { return p.limits.raytrace_range; })
      .def_readonly("static_tolerance", &LayerParams::static_tolerance)
      .def_readonly("robot_name", &LayerParams::robot_name)
      .def_readonly("trigger_debounce", &LayerParams::trigger_debounce)
      .def_readonly("clearing_margin", &LayerParams::clearing_margin)
      .def_readonly("clearing_scans", &LayerParams::clearing_scans)
      .def_readonly("clearing_time", &LayerParams::clearing_time)
      .def_readonly("clearing_neighbours", &LayerParams::clearing_neighbours)
      .def_readonly("trigger_memory", &LayerParams::trigger_memory)
      .def_readonly("trigger_radius", &LayerParams::trigger_radius)
      .def_readonly("inscribed_radius", &LayerParams::inscribed_radius)
      .def_readonly("memory_on_stuck_feedback", &LayerParams::memory_on_stuck_feedback)
      .def_readonly("lease_renewal_interval", &LayerParams::lease_renewal_interval);

  py::class_<ObstacleUpdate>(m, "ObstacleUpdate", "Value of one sharing_msgs/SharedObstacle")
      .def(py::init([](const std::string& uuid, const py::object& marked, const py::object& cleared,
                       std::uint32_t deadline, const std::vector<double>& rectangle, const std::string& source,
                       const GridGeometry& geometry, std::uint64_t version, double stamp) {
             ObstacleUpdate u;
             u.uuid = uuid;
             u.marked = toCells(marked, "marked");
             u.cleared = toCells(cleared, "cleared");
             u.deadline = deadline;
             u.rectangle = toSubsection(rectangle);
             u.source = source;
             u.geometry = geometry;
             u.version = version;
             u.stamp = stamp;
             return u;
           }),
           py::arg("uuid"), py::arg("marked"), py::arg("cleared"), py::arg("deadline"), py::arg("rectangle"),
           py::arg("source"), py::arg("geometry"), py::arg("version"), py::arg("stamp") = 0.0)
      .def_readonly("uuid", &ObstacleUpdate::uuid)
      .def_property_readonly("marked", [](const ObstacleUpdate& u) { return toArray(u.marked); })
      .def_property_readonly("cleared", [](const ObstacleUpdate& u) { return toArray(u.cleared); })
      .def_readonly("deadline", &ObstacleUpdate::deadline)
      .def_property_readonly("rectangle",
                             [](const ObstacleUpdate& u) {
                               return std::vector<double>{ u.rectangle.min_x, u.rectangle.min_y, u.rectangle.max_x,
                                                           u.rectangle.max_y };
                             })
      .def_readonly("source", &ObstacleUpdate::source)
      .def_readonly("geometry", &ObstacleUpdate::geometry)
      .def_readonly("version", &ObstacleUpdate::version)
      .def_readonly("stamp", &ObstacleUpdate::stamp);

  py::class_<Proposal>(m, "Proposal")
      .def_property_readonly("cells", [](const Proposal& p) { return toArray(p.cells); })
      .def_property_readonly("rectangle", [](const Proposal& p) {
        return std::vector<double>{ p.rectangle.min_x, p.rectangle.min_y, p.rectangle.max_x, p.rectangle.max_y };
      });

  py::class_<ApplyResult>(m, "ApplyResult")
      .def_readonly("ok", &ApplyResult::ok)
      .def_readonly("added", &ApplyResult::added)
      .def_readonly("changed", &ApplyResult::changed)
      .def_readonly("error", &ApplyResult::error)
      .def("__bool__", [](const ApplyResult& r) { return r.ok; });

  py::class_<TriggerReport>(m, "TriggerReport", "What a trigger did: proposals, or the reason why none")
      .def_property_readonly("source", [](const TriggerReport& r) { return std::string(triggerSourceName(r.source)); })
      .def_property_readonly("reason", [](const TriggerReport& r) { return std::string(triggerReasonName(r.reason)); })
      .def_readonly("log", &TriggerReport::log)
      .def_readonly("proposals", &TriggerReport::proposals)
      .def_readonly("message", &TriggerReport::message)
      .def("__repr__", [](const TriggerReport& r) {
        return "TriggerReport(" + std::string(triggerSourceName(r.source)) + ", " + triggerReasonName(r.reason) +
               ", " + std::to_string(r.proposals.size()) + " proposals)";
      });

  py::class_<ScanOutcome>(m, "ScanOutcome")
      .def_property_readonly("marked", [](const ScanOutcome& o) { return toArray(o.touch.marked); })
      .def_property_readonly("watched_cleared", [](const ScanOutcome& o) { return toArray(o.touch.watched_cleared); })
      .def_property_readonly("watched_free", [](const ScanOutcome& o) { return toArray(o.touch.watched_free); })
      .def_property_readonly("watched_hit", [](const ScanOutcome& o) { return toArray(o.touch.watched_hit); })
      .def_property_readonly("origin_in_map", [](const ScanOutcome& o) { return o.touch.origin_in_map; })
      .def_property_readonly("rejected_points", [](const ScanOutcome& o) { return o.touch.rejected_points; })
      .def_property_readonly("height_filtered", [](const ScanOutcome& o) { return o.touch.height_filtered; })
      .def_readonly("updates", &ScanOutcome::updates);

  bindFleetRobots(m);
  py::class_<SharingCore>(m, "SharingCore", "The sharing layer without ROS; times are seconds, passed in")
      .def(py::init<const GridGeometry&, const LayerParams&>(), py::arg("geometry"), py::arg("params"))
      .def_property_readonly("geometry", &SharingCore::geometry)
      .def_property_readonly("params", &SharingCore::params)
      .def("set_static_map",
           [](SharingCore& core, py::array_t<std::uint8_t, py::array::c_style | py::array::forcecast> costs) {
             core.setStaticMap(costs.data(), static_cast<std::size_t>(costs.size()));
           },
           py::arg("costs"), "Static layer costs (size_y x size_x); cells >= static_occupied_cost are walls")
      .def("process_scan",
           [](SharingCore& core, const std::tuple<double, double, double>& origin, const DoubleArray& points,
              double now) {
             Observation obs = toObservation(origin, points);
             py::gil_scoped_release release;
             return core.processScan(obs, now);
           },
           py::arg("origin"), py::arg("points"), py::arg("now"),
           "Clear and mark one observation ((N, 3) points in the grid frame); returns a ScanOutcome")
      .def("signal_stuck", &SharingCore::signalStuck, py::arg("now"),
           "A cannot-get-past signal; True when it starts a burst")
      .def("propose", &SharingCore::propose, py::arg("robot_x"), py::arg("robot_y"), py::arg("use_memory") = false,
           "Proposals from the shareable cells (with use_memory also the remembered cells within trigger_radius "
           "beyond obstacle_range)")
      .def("set_unknown_map",
           [](SharingCore& core, const py::object& mask) {
             if (mask.is_none())
             {
               core.setUnknownMap(nullptr, 0);
               return;
             }
             auto arr = py::array_t<std::uint8_t, py::array::c_style | py::array::forcecast>::ensure(mask);
             if (!arr)
             {
               throw py::value_error("set_unknown_map: expected an array (non-zero = unknown) or None");
             }
             core.setUnknownMap(arr.data(), static_cast<std::size_t>(arr.size()));
           },
           py::arg("unknown"),
           "Where the a-priori map is unknown (size_y x size_x, non-zero = unknown, e.g. OccupancyGrid == -1); "
           "those cells and cells within static_tolerance of them are never shared. None forgets it")
      .def("trigger",
           [](SharingCore& core, const std::string& source, double now, double robot_x, double robot_y) {
             return core.trigger(parseTriggerSource(source), now, robot_x, robot_y);
           },
           py::arg("source"), py::arg("now"), py::arg("robot_x"), py::arg("robot_y"),
           "A stuck trigger (source 'stuck_feedback', 'recovery_status' or 'manual'): debounced, then proposals "
           "or the reason why none, as a TriggerReport")
      .def("set_plan",
           [](SharingCore& core, const py::object& poses) {
             std::vector<std::pair<double, double>> plan;
             py::array arr = py::array::ensure(poses);
             if (!arr)
             {
               throw py::value_error("set_plan: expected an (N, 2) array of x, y");
             }
             if (arr.size() != 0)
             {
               auto xy = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(arr);
               if (!xy || xy.ndim() != 2 || xy.shape(1) < 2)
               {
                 throw py::value_error("set_plan: expected an (N, 2) array of x, y; got " +
                                       std::to_string(arr.ndim()) + " dims");
               }
               const std::size_t cols = static_cast<std::size_t>(xy.shape(1));
               for (py::ssize_t i = 0; i < xy.shape(0); ++i)
               {
                 plan.emplace_back(xy.data()[i * cols], xy.data()[i * cols + 1]);
               }
             }
             core.setPlan(plan);
           },
           py::arg("poses"), "The current global plan as (N, 2) world x, y (extra columns ignored); empty: none")
      .def_property_readonly("plan_length", [](const SharingCore& core) { return core.plan().size(); })
      .def("check_plan", &SharingCore::checkPlan, py::arg("robot_x"), py::arg("robot_y"), py::arg("now"),
           "The plan-blocked trigger, after each process_scan; reason 'none' when nothing new is on the plan")
      .def("remembered_cells", [](const SharingCore& core) { return toArray(core.rememberedCells()); })
      .def("apply_shared", &SharingCore::applyShared, py::arg("update"), py::arg("now"))
      .def("expire", &SharingCore::expire, py::arg("uuid"))
      .def("reset_obstacle_layer", &SharingCore::resetObstacleLayer)
      .def("clear_obstacles_outside", &SharingCore::clearObstaclesOutside, py::arg("x0"), py::arg("y0"),
           py::arg("x1"), py::arg("y1"),
           "ClearCostmapRecovery's clearArea: obstacle cells outside the open cell window (x0, x1) x (y0, y1) "
           "are cleared and no longer shareable; shared obstacles stay. Returns how many were cleared.")
      .def("draw_shared",
           [](const SharingCore& core, py::array_t<std::uint8_t, py::array::c_style> master) {
             core.drawShared(master.mutable_data(), static_cast<std::size_t>(master.size()));
           },
           py::arg("master"), "Draws present shared cells as lethal into a uint8 master grid, in place")
      .def("take_dirty_bounds",
           [](SharingCore& core) -> py::object {
             const WorldBounds b = core.takeDirtyBounds();
             if (b.empty())
             {
               return py::none();
             }
             return py::make_tuple(b.min_x, b.min_y, b.max_x, b.max_y);
           })
      .def("obstacle_grid",
           [](py::object self) {
             SharingCore& core = self.cast<SharingCore&>();
             const GridGeometry& g = core.geometry();
             // A view into the core's grid, kept alive by the core object.
             return py::array_t<std::uint8_t>({ static_cast<py::ssize_t>(g.size_y), static_cast<py::ssize_t>(g.size_x) },
                                              core.obstacleGrid().data(), self);
           },
           "The obstacle layer's grid as a (size_y, size_x) uint8 view (no copy)")
      .def("shareable_cells", [](const SharingCore& core) { return toArray(core.shareableCells()); })
      .def_property_readonly("fleet_robots", py::overload_cast<>(&SharingCore::fleetRobots),
                             py::return_value_policy::reference_internal,
                             "The fleet robots whose footprints (plus margin) are never shared (FleetRobots)")
      .def("shared_uuids",
           [](const SharingCore& core) {
             std::vector<std::string> uuids;
             for (const auto& entry : core.sharedObstacles())
             {
               uuids.push_back(entry.first);
             }
             return uuids;
           })
      .def("shared_cells", [](const SharingCore& core, const std::string& uuid) { return toArray(core.sharedCells(uuid)); })
      .def("shared_rectangle",
           [](const SharingCore& core, const std::string& uuid) -> py::object {
             const auto found = core.sharedObstacles().find(uuid);
             if (found == core.sharedObstacles().end())
             {
               return py::none();
             }
             const Subsection& s = found->second.rectangle;
             return py::cast(std::vector<double>{ s.min_x, s.min_y, s.max_x, s.max_y });
           })
      .def("shared_max_version",
           [](const SharingCore& core, const std::string& uuid) -> py::object {
             const auto found = core.sharedObstacles().find(uuid);
             if (found == core.sharedObstacles().end())
             {
               return py::none();
             }
             return py::cast(found->second.max_version);
           })
      // Times the same processScan natively, so the benchmark can state the binding overhead as a ratio.
      .def("_time_process_scan_native",
           [](SharingCore& core, const std::tuple<double, double, double>& origin, const DoubleArray& points,
              double now, int repeats) {
             Observation obs = toObservation(origin, points);
             std::vector<double> times;
             py::gil_scoped_release release;
             for (int i = 0; i < repeats; ++i)
             {
               const auto start = std::chrono::steady_clock::now();
               ScanOutcome outcome = core.processScan(obs, now);
               const auto stop = std::chrono::steady_clock::now();
               times.push_back(std::chrono::duration<double>(stop - start).count());
             }
             return times;
           });
}
