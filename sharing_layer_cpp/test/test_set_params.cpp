// SharingCore::setParams: new parameters on a running core (the plugin's dynamic_reconfigure, issue 28), validated,
// applied from the next call on, with the grids, shared obstacles and trigger memory kept.
#include <gtest/gtest.h>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <vector>

#include "sharing_layer/sharing_core.h"
#include "sim_scan.h"

using namespace sharing_layer;
using namespace sharing_layer::test;

namespace
{
std::vector<std::uint8_t> gridCopy(const SharingCore& core)
{
  const CostGrid& grid = core.obstacleGrid();
  return std::vector<std::uint8_t>(grid.data(), grid.data() + core.geometry().cellCount());
}

bool anyWithinX(const std::vector<std::uint32_t>& cells, unsigned int x0, unsigned int x1)
{
  const GridGeometry g = grid();
  return std::any_of(cells.begin(), cells.end(), [&](std::uint32_t index) {
    unsigned int mx = 0, my = 0;
    g.indexToCells(index, mx, my);
    return mx >= x0 && mx <= x1;
  });
}
}  // namespace

TEST(SetParams, NewValuesApplyAndTheGridSharedObstaclesAndMemoryStay)
{
  SimWorld world = walledWorld();
  world.box(5.52, 4.8, 5.72, 5.2);  // a crate
  SharingCore core = makeCore();
  core.processScan(world.scan(5.0, 5.0, 0.0), 1.0);
  ASSERT_TRUE(core.applyShared(sharedUpdate("block", { grid().getIndex(60, 60), grid().getIndex(61, 60) },
                                            Subsection(3.0, 3.0, 3.1, 3.05)),
                               1.0)
                  .ok);
  const std::vector<std::uint8_t> before = gridCopy(core);
  const std::vector<std::uint32_t> shareable = core.shareableCells(), remembered = core.rememberedCells();
  ASSERT_FALSE(shareable.empty());

  LayerParams changed = core.params();
  changed.trigger_radius = 1.5;
  changed.trigger_memory = 10.0;
  changed.clearing_scans = 5;
  changed.clearing_time = 2.5;
  changed.clearing_margin = 0.3;
  changed.clearing_neighbours = 2;
  changed.inscribed_radius = 0.4;
  changed.memory_on_stuck_feedback = true;
  changed.lease_renewal_interval = 1.0;
  core.setParams(changed);

  EXPECT_EQ(1.5, core.params().trigger_radius);
  EXPECT_EQ(10.0, core.params().trigger_memory);
  EXPECT_EQ(5u, core.params().clearing_scans);
  EXPECT_EQ(2.5, core.params().clearing_time);
  EXPECT_EQ(0.3, core.params().clearing_margin);
  EXPECT_EQ(2u, core.params().clearing_neighbours);
  EXPECT_EQ(0.4, core.params().inscribed_radius);
  EXPECT_TRUE(core.params().memory_on_stuck_feedback);
  EXPECT_EQ(1.0, core.params().lease_renewal_interval);
  EXPECT_EQ(before, gridCopy(core)) << "the obstacle grid stays";
  EXPECT_EQ(shareable, core.shareableCells());
  EXPECT_EQ(remembered, core.rememberedCells());
  ASSERT_EQ(1u, core.sharedObstacles().size());
  EXPECT_EQ(2u, core.sharedCells("block").size());
}

TEST(SetParams, ABadValueIsRefusedNamingItAndChangesNothing)
{
  SharingCore core = makeCore();
  LayerParams bad = core.params();
  bad.trigger_radius = 2.0;   // a good change ...
  bad.clearing_scans = 0;     // ... with a bad one: nothing applies
  try
  {
    core.setParams(bad);
    FAIL() << "clearing_scans 0 accepted";
  }
  catch (const std::invalid_argument& e)
  {
    EXPECT_NE(std::string::npos, std::string(e.what()).find("clearing_scans")) << e.what();
  }
  EXPECT_EQ(3u, core.params().clearing_scans);
  EXPECT_EQ(4.0, core.params().trigger_radius);

  LayerParams negative = core.params();
  negative.trigger_debounce = -1.0;
  EXPECT_THROW(core.setParams(negative), std::invalid_argument);
  EXPECT_EQ(2.0, core.params().trigger_debounce);
  negative = core.params();
  negative.static_tolerance = -2;
  EXPECT_THROW(core.setParams(negative), std::invalid_argument);
  EXPECT_EQ(3, core.params().static_tolerance);
}

TEST(SetParams, ANewTriggerDebounceAppliesFromTheNextSignal)
{
  SharingCore core = makeCore();  // trigger_debounce 2 s
  EXPECT_TRUE(core.signalStuck(1.0));
  EXPECT_FALSE(core.signalStuck(2.0));
  LayerParams shorter = core.params();
  shorter.trigger_debounce = 0.5;
  core.setParams(shorter);
  EXPECT_TRUE(core.signalStuck(3.0)) << "1 s after the last signal: a new burst with a 0.5 s window";
  EXPECT_FALSE(core.signalStuck(3.4));
}

TEST(SetParams, AWiderStaticToleranceDropsShareableCellsNearWallsAndANarrowerOneLetsThemBack)
{
  // The static map's walls are cells 0..3; a crate 0.4..0.55 m from the map's edge (cells 8..10) lies beyond
  // static_tolerance 3 (cells up to 6 are static) but within 8.
  SimWorld world = walledWorld();
  world.box(0.40, 4.8, 0.55, 5.2);
  SharingCore core = makeCore();
  core.processScan(world.scan(1.5, 5.0, 3.14159265358979), 1.0);
  ASSERT_TRUE(anyWithinX(core.shareableCells(), 8, 10)) << "the crate is shareable with static_tolerance 3";

  LayerParams wide = core.params();
  wide.static_tolerance = 8;
  core.setParams(wide);
  EXPECT_FALSE(anyWithinX(core.shareableCells(), 0, 11)) << "within 8 cells of a wall: static now";
  EXPECT_FALSE(anyWithinX(core.rememberedCells(), 0, 11));
  core.processScan(world.scan(1.5, 5.0, 3.14159265358979), 1.1);
  EXPECT_FALSE(anyWithinX(core.shareableCells(), 0, 11)) << "and stays so at the next scan";

  LayerParams narrow = core.params();
  narrow.static_tolerance = 3;
  core.setParams(narrow);
  core.processScan(world.scan(1.5, 5.0, 3.14159265358979), 1.2);
  EXPECT_TRUE(anyWithinX(core.shareableCells(), 8, 10)) << "shareable again once seen with static_tolerance 3";
}
