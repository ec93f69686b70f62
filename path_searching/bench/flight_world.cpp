// The worlds of make bench-flight: a seeded map of one style over the simulator's forest area,
// saved as an OctoMap for simulation.launch map_file:=, and a mission's goals drawn in the open (at
// the two ends, outside the area) or beside obstacles (inside it, 0.5-0.8 m from the nearest one),
// each verified reachable from the one before with the global route (path_searching GlobalRouter)
// on the true map, at the planner's clearance and height band. Prints
//   GOALS x y z x y z ...
//   KINDS open near ...
// on stdout; the reasons for redrawn goals on stderr.
//
//   flight_world --style forest|walls|windows|rings|boxes|mixed --density low|medium|high --seed N
//                --goals N --out FILE.bt [--near-fraction F] [--start X Y Z]
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "topo_planner/path_searching/global_router.h"
#include "topo_planner/plan_env/map_io.h"
#include "topo_planner/plan_env/synthetic_scene.h"

using namespace topo_planner;

namespace {

int usage(const char* why) {
  std::fprintf(stderr,
               "flight_world: %s\nusage: flight_world --style forest|walls|windows|rings|boxes|mixed "
               "--density low|medium|high --seed N --goals N --out FILE.bt [--near-fraction F] [--start X Y Z]\n",
               why);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::string style = "forest", density = "medium", out;
  uint32_t seed = 1;
  int goals = 3;
  double near_fraction = 0.5;
  Eigen::Vector3d start(-15.0, 0.0, 1.0);
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> const char* { return i + 1 < argc ? argv[++i] : nullptr; };
    const char* v = a == "--start" ? nullptr : next();
    if (a == "--style" && v) style = v;
    else if (a == "--density" && v) density = v;
    else if (a == "--seed" && v) seed = uint32_t(std::strtoul(v, nullptr, 10));
    else if (a == "--goals" && v) goals = std::atoi(v);
    else if (a == "--out" && v) out = v;
    else if (a == "--near-fraction" && v) near_fraction = std::atof(v);
    else if (a == "--start" && i + 3 < argc) {
      for (int k = 0; k < 3; ++k) start[k] = std::atof(argv[++i]);
    } else {
      return usage(("bad argument " + a).c_str());
    }
  }
  if (out.empty() || goals < 1 || goals > 50 || !(near_fraction >= 0.0 && near_fraction <= 1.0)) return usage("bad arguments");
  ObstacleDensity d;
  if (density == "low") d = ObstacleDensity::kLow;
  else if (density == "medium") d = ObstacleDensity::kMedium;
  else if (density == "high") d = ObstacleDensity::kHigh;
  else return usage("density must be low, medium or high");

  // The map generator's styles (ForestConfig::applyStyle, as the simulator's map_generator_node).
  ForestConfig f = ForestConfig::preset(d);
  if (!f.applyStyle(style)) return usage("unknown style");
  // The simulator's forest area and scenario (launch/simulation.launch, config/map_generator.yaml).
  const Eigen::Vector3d area_min(-12.0, -10.0, 0.0), area_max(12.0, 10.0, 3.0);
  f.keep_free = {start};
  f.keep_free_radius_m = 1.5;
  f.ground_z_m = area_min.z();
  f.pillar_height_m = area_max.z() - area_min.z();
  std::string why;
  if (!f.validate(&why)) return usage(why.c_str());
  SyntheticScene area(area_max - area_min, 0.1, area_min);
  generateForest(f, seed, area.occupancy.get());
  const MapStatus saved = saveOctomapFile(*area.occupancy, out, &why);
  if (saved != MapStatus::kSuccess) {
    std::fprintf(stderr, "flight_world: cannot save %s: %s\n", out.c_str(), why.c_str());
    return 1;
  }

  // The world the vehicle flies in: the area inside the planner's window of the bench (x in
  // [-20, 20], y within the area, z from 0 to 3.5), free around it.
  SyntheticScene world(Eigen::Vector3d(40.0, area_max.y() - area_min.y(), 3.5), 0.1,
                       Eigen::Vector3d(-20.0, area_min.y(), 0.0));
  area.occupancy->forEachOccupied([&](const Eigen::Vector3i& i) { world.occupancy->setState(i, VoxelState::kOccupied); });
  const EsdfMap& map = world.finish();
  GlobalRouter::Config rc;  // the planner's route (config/planner.yaml), on the true map: all known
  rc.unknown_is_free = false;
  rc.min_z_m = 0.3;
  rc.max_z_m = 3.0;
  GlobalRouter router(rc);

  uint32_t style_hash = 2166136261u;  // FNV-1a: each style draws its own goals
  for (const char ch : style) style_hash = (style_hash ^ uint8_t(ch)) * 16777619u;
  std::mt19937 rng(seed * 7919u + style_hash);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<Eigen::Vector3d> drawn;
  std::vector<std::string> kinds;
  Eigen::Vector3d from = start;
  for (int k = 0; k < goals; ++k) {
    const double side = k % 2 == 0 ? 1.0 : -1.0;  // the far end first, then back
    bool ok = false;
    const bool near = u01(rng) < near_fraction;  // drawn once: the redraws below keep the kind
    for (int attempt = 0; attempt < 2000 && !ok; ++attempt) {
      Eigen::Vector3d g;
      if (near) {  // inside the area near this end, 0.5-0.8 m from the nearest obstacle
        g = Eigen::Vector3d(side * (6.0 + 5.5 * u01(rng)), -9.0 + 18.0 * u01(rng), 0.8 + 1.2 * u01(rng));
        const double c = map.query(g).distance;
        if (!(c >= 0.5 && c <= 0.8)) continue;
      } else {  // beyond the area, in the open
        g = Eigen::Vector3d(side * 15.0, -8.0 + 16.0 * u01(rng), 0.8 + 0.8 * u01(rng));
        if (!(map.query(g).distance >= 1.0)) continue;
      }
      const GlobalRouter::Result r = router.route(map, from, g);
      if (r.status != SearchStatus::kSuccess) {
        std::fprintf(stderr, "flight_world: goal %d candidate (%.2f %.2f %.2f) redrawn: no route (%s)\n", k, g.x(), g.y(),
                     g.z(), toString(r.status));
        continue;
      }
      g = (g * 100.0).array().round() / 100.0;
      drawn.push_back(g);
      kinds.push_back(near ? "near" : "open");
      from = g;
      ok = true;
    }
    if (!ok) {
      std::fprintf(stderr, "flight_world: no reachable goal %d after 2000 draws\n", k);
      return 1;
    }
  }
  std::printf("GOALS");
  for (const Eigen::Vector3d& g : drawn) std::printf(" %.2f %.2f %.2f", g.x(), g.y(), g.z());
  std::printf("\nKINDS");
  for (const std::string& s : kinds) std::printf(" %s", s.c_str());
  std::printf("\n");
  return 0;
}
