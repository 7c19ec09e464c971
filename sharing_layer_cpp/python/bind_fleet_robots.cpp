// pybind11 face of FleetRobots (fleet robots are never shared), kept beside bindings.cpp so that
// the module's main file only registers it.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cstring>
#include <string>
#include <tuple>
#include <vector>

#include "sharing_layer/fleet_robots.h"

namespace py = pybind11;

namespace sharing_layer
{
namespace
{
/// An (N, 2) array (or sequence of pairs) of world x, y; extra columns are refused.
std::vector<std::pair<double, double>> toPolygon(const py::object& obj)
{
  auto arr = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(obj);
  if (!arr)
  {
    throw py::value_error("footprint: expected an (N, 2) array of x, y");
  }
  if (arr.size() == 0)
  {
    return {};
  }
  if (arr.ndim() != 2 || arr.shape(1) != 2)
  {
    throw py::value_error("footprint: expected an (N, 2) array of x, y; got " + std::to_string(arr.ndim()) +
                          " dims");
  }
  std::vector<std::pair<double, double>> polygon;
  for (py::ssize_t i = 0; i < arr.shape(0); ++i)
  {
    polygon.emplace_back(arr.data()[2 * i], arr.data()[2 * i + 1]);
  }
  return polygon;
}

py::array_t<double> fromPolygon(const std::vector<std::pair<double, double>>& polygon)
{
  py::array_t<double> out({ static_cast<py::ssize_t>(polygon.size()), static_cast<py::ssize_t>(2) });
  for (std::size_t i = 0; i < polygon.size(); ++i)
  {
    out.mutable_data()[2 * i] = polygon[i].first;
    out.mutable_data()[2 * i + 1] = polygon[i].second;
  }
  return out;
}

py::array_t<std::uint32_t> cellArray(const std::vector<std::uint32_t>& cells)
{
  py::array_t<std::uint32_t> out(static_cast<py::ssize_t>(cells.size()));
  if (!cells.empty())
  {
    std::memcpy(out.mutable_data(), cells.data(), cells.size() * sizeof(std::uint32_t));
  }
  return out;
}

FleetRobot makeRobot(const std::string& name, const py::object& footprint, double stamp)
{
  FleetRobot robot;
  robot.name = name;
  robot.footprint = toPolygon(footprint);
  robot.stamp = stamp;
  return robot;
}
}  // namespace

void bindFleetRobots(py::module& m)
{
  py::class_<FleetRobots>(m, "FleetRobots",
                          "Fleet robots' footprints (grid frame) whose cells plus a margin the layer never shares; "
                          "get it from SharingCore.fleet_robots. Bad input raises ValueError and changes nothing.")
      .def_property_readonly("margin", [](const FleetRobots& r) { return r.params().margin; })
      .def_property_readonly("timeout", [](const FleetRobots& r) { return r.params().timeout; })
      .def_property_readonly("trail", [](const FleetRobots& r) { return r.params().trail; })
      .def(
          "set_params",
          [](FleetRobots& r, double margin, double timeout, double trail) {
            r.setParams(FleetRobotParams{ margin, timeout, trail });
          },
          py::arg("margin") = 0.2, py::arg("timeout") = 3.0, py::arg("trail") = 1.0,
          "robot_exclusion_margin (m), robot_timeout (s, 0 = never forget) and robot_exclusion_trail (s, 0..10)")
      .def("update",
           [](FleetRobots& r, const std::string& name, const py::object& footprint, double stamp) {
             r.update(makeRobot(name, footprint, stamp));
           },
           py::arg("name"), py::arg("footprint"), py::arg("stamp"),
           "Adds or refreshes one robot: its footprint at its pose as (N, 2) world x, y, refreshed at stamp (s)")
      .def("replace_all",
           [](FleetRobots& r, const std::vector<std::tuple<std::string, py::object, double>>& robots) {
             std::vector<FleetRobot> all;
             for (const auto& item : robots)
             {
               all.push_back(makeRobot(std::get<0>(item), std::get<1>(item), std::get<2>(item)));
             }
             r.replaceAll(all);
           },
           py::arg("robots"), "The whole known set as [(name, footprint, stamp)]; robots not in it are forgotten")
      .def("forget", &FleetRobots::forget, py::arg("name"))
      .def("clear", &FleetRobots::clear)
      .def("expire", &FleetRobots::expire, py::arg("now"), "Forgets robots not refreshed within timeout; their names")
      .def("names", &FleetRobots::names)
      .def("__len__", &FleetRobots::size)
      .def("footprint",
           [](const FleetRobots& r, const std::string& name) -> py::object {
             const auto found = r.robots().find(name);
             return found == r.robots().end() ? py::none() : py::object(fromPolygon(found->second.footprint));
           },
           py::arg("name"))
      .def("stamp",
           [](const FleetRobots& r, const std::string& name) -> py::object {
             const auto found = r.robots().find(name);
             return found == r.robots().end() ? py::none() : py::object(py::float_(found->second.stamp));
           },
           py::arg("name"))
      .def("excluded_cells", [](const FleetRobots& r) { return cellArray(r.excludedCells()); })
      .def("robots_at", &FleetRobots::robotsAt, py::arg("index"))
      .def_static(
          "rasterize",
          [](const GridGeometry& g, const py::object& footprint, double margin) {
            return cellArray(FleetRobots::rasterize(g, toPolygon(footprint), margin));
          },
          py::arg("geometry"), py::arg("footprint"), py::arg("margin"));
}

}  // namespace sharing_layer
