// pybind11 module over the navigation host's ROS-free core (inflation, global planner). Grids cross
// as (size_y, size_x) uint8 NumPy arrays without copies; planning and inflation release the GIL.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "fleet_nav/grid_planner.h"
#include "fleet_nav/inflation.h"

namespace py = pybind11;
using namespace fleet_nav;

namespace
{
using Grid = py::array_t<std::uint8_t, py::array::c_style>;

void checkGrid(const Grid& grid, const char* what)
{
  if (grid.ndim() != 2 || grid.shape(0) == 0 || grid.shape(1) == 0)
  {
    throw py::value_error(std::string(what) + ": expected a non-empty 2-D uint8 array (size_y, size_x)");
  }
}

py::array_t<std::uint32_t> toArray(const std::vector<std::uint32_t>& cells)
{
  py::array_t<std::uint32_t> out(static_cast<py::ssize_t>(cells.size()));
  if (!cells.empty())
  {
    std::memcpy(out.mutable_data(), cells.data(), cells.size() * sizeof(std::uint32_t));
  }
  return out;
}

std::uint32_t cellIndex(const std::pair<long, long>& cell, unsigned int size_x, unsigned int size_y, bool& ok)
{
  ok = cell.first >= 0 && cell.second >= 0 && cell.first < static_cast<long>(size_x) &&
       cell.second < static_cast<long>(size_y);
  return ok ? static_cast<std::uint32_t>(cell.second) * size_x + static_cast<std::uint32_t>(cell.first) : 0;
}
}  // namespace

PYBIND11_MODULE(_nav_core, m)
{
  m.doc() = "ROS-free core of fleet_nav: costmap_2d inflation and an A* global planner";

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

  py::class_<Inflator>(m, "Inflator", "costmap_2d InflationLayer costs by exact distance transform")
      .def(py::init([](double resolution, double inscribed_radius, double inflation_radius,
                       double cost_scaling_factor) {
             InflationParams p;
             p.resolution = resolution;
             p.inscribed_radius = inscribed_radius;
             p.inflation_radius = inflation_radius;
             p.cost_scaling_factor = cost_scaling_factor;
             return Inflator(p);
           }),
           py::arg("resolution"), py::arg("inscribed_radius"), py::arg("inflation_radius"),
           py::arg("cost_scaling_factor"))
      .def_property_readonly("cell_radius", &Inflator::cellRadius)
      .def("cost_at_distance", &Inflator::costAtDistance, py::arg("distance_cells"))
      .def("inflate",
           [](Inflator& inflator, const Grid& master, Grid out, unsigned int min_x, unsigned int min_y,
              unsigned int max_x, unsigned int max_y) {
             checkGrid(master, "inflate master");
             checkGrid(out, "inflate out");
             if (out.shape(0) != master.shape(0) || out.shape(1) != master.shape(1))
             {
               throw py::value_error("inflate: out and master must have the same shape");
             }
             const auto sx = static_cast<unsigned int>(master.shape(1));
             const auto sy = static_cast<unsigned int>(master.shape(0));
             std::uint8_t* dst = out.mutable_data();
             py::gil_scoped_release release;
             inflator.inflate(master.data(), sx, sy, dst, min_x, min_y, max_x, max_y);
           },
           py::arg("master"), py::arg("out"), py::arg("min_x"), py::arg("min_y"), py::arg("max_x"), py::arg("max_y"),
           "Inflates master into out (in place) over the cell window [min_x, max_x) x [min_y, max_y)")
      .def("inflate_all",
           [](Inflator& inflator, const Grid& master) {
             checkGrid(master, "inflate_all master");
             Grid out({ master.shape(0), master.shape(1) });
             const auto sx = static_cast<unsigned int>(master.shape(1));
             const auto sy = static_cast<unsigned int>(master.shape(0));
             std::uint8_t* dst = out.mutable_data();
             {
               py::gil_scoped_release release;
               inflator.inflateAll(master.data(), sx, sy, dst);
             }
             return out;
           },
           py::arg("master"), "A new inflated copy of master");

  py::enum_<PlanStatus>(m, "PlanStatus")
      .value("OK", PlanStatus::Ok)
      .value("START_OFF_GRID", PlanStatus::StartOffGrid)
      .value("GOAL_OFF_GRID", PlanStatus::GoalOffGrid)
      .value("GOAL_BLOCKED", PlanStatus::GoalBlocked)
      .value("NO_PATH", PlanStatus::NoPath);
  m.def("describe", &describe, py::arg("status"), "A short English reason for a PlanStatus");

  py::class_<GridPlanner>(m, "GridPlanner", "A* on an 8-connected costmap (global_planner cost model)")
      .def(py::init([](double neutral_cost, double cost_factor, int lethal_cost, bool allow_unknown,
                       int unknown_cost, unsigned int escape_cells) {
             if (lethal_cost < 1 || lethal_cost > 254)
             {
               throw py::value_error("lethal_cost must be 1..254, got " + std::to_string(lethal_cost));
             }
             if (unknown_cost < 0 || unknown_cost > 254)
             {
               throw py::value_error("unknown_cost must be 0..254, got " + std::to_string(unknown_cost));
             }
             PlannerParams p;
             p.neutral_cost = neutral_cost;
             p.cost_factor = cost_factor;
             p.lethal_cost = static_cast<std::uint8_t>(lethal_cost);
             p.allow_unknown = allow_unknown;
             p.unknown_cost = static_cast<std::uint8_t>(unknown_cost);
             p.escape_cells = escape_cells;
             return GridPlanner(p);
           }),
           py::arg("neutral_cost") = 50.0, py::arg("cost_factor") = 3.0, py::arg("lethal_cost") = 253,
           py::arg("allow_unknown") = true, py::arg("unknown_cost") = 200, py::arg("escape_cells") = 10)
      .def("make_plan",
           [](GridPlanner& planner, const Grid& costs, std::pair<long, long> start, std::pair<long, long> goal,
              py::object window) {
             checkGrid(costs, "make_plan costs");
             const auto sx = static_cast<unsigned int>(costs.shape(1));
             const auto sy = static_cast<unsigned int>(costs.shape(0));
             bool start_ok = false, goal_ok = false;
             const std::uint32_t s = cellIndex(start, sx, sy, start_ok);
             const std::uint32_t g = cellIndex(goal, sx, sy, goal_ok);
             std::vector<std::uint32_t> path;
             if (!start_ok)
             {
               return py::make_tuple(PlanStatus::StartOffGrid, toArray(path));
             }
             if (!goal_ok)
             {
               return py::make_tuple(PlanStatus::GoalOffGrid, toArray(path));
             }
             CellWindow win;
             const CellWindow* win_ptr = nullptr;
             if (!window.is_none())
             {
               const auto w = window.cast<std::vector<long>>();
               if (w.size() != 4 || w[0] < 0 || w[1] < 0 || w[2] < w[0] || w[3] < w[1])
               {
                 throw py::value_error("make_plan: window must be (min_x, min_y, max_x, max_y) cells, min <= max");
               }
               win = CellWindow{ static_cast<unsigned int>(w[0]), static_cast<unsigned int>(w[1]),
                                 static_cast<unsigned int>(w[2]), static_cast<unsigned int>(w[3]) };
               win_ptr = &win;
             }
             PlanStatus status;
             {
               py::gil_scoped_release release;
               status = planner.makePlan(costs.data(), sx, sy, s, g, path, win_ptr);
             }
             return py::make_tuple(status, toArray(path));
           },
           py::arg("costs"), py::arg("start"), py::arg("goal"), py::arg("window") = py::none(),
           "Plans from cell start=(mx, my) to goal=(mx, my); returns (PlanStatus, uint32 flat indexes start..goal)")
      .def_property_readonly("last_expansions", &GridPlanner::lastExpansions)
      .def_property_readonly("last_cost", &GridPlanner::lastCost);

  m.def("first_blocked",
        [](const Grid& costs, const py::array_t<std::uint32_t, py::array::c_style | py::array::forcecast>& path,
           std::size_t from, std::size_t count, int lethal_cost) {
          checkGrid(costs, "first_blocked costs");
          std::vector<std::uint32_t> cells(path.data(), path.data() + path.size());
          return firstBlocked(costs.data(), static_cast<std::size_t>(costs.size()), cells, from, count,
                              static_cast<std::uint8_t>(lethal_cost));
        },
        py::arg("costs"), py::arg("path"), py::arg("from_index"), py::arg("count"), py::arg("lethal_cost") = 253,
        "First position in path[from_index:from_index+count] whose cost is >= lethal_cost (not unknown); -1 if none");
}
