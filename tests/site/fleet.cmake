# Fleet simulator (algo/src/sim/fleet*.cpp, docs/design/fleet_sim.md): small sites built in code,
# at most 6 vehicles for a minute (the 20-vehicle, 10-minute run is tests/bench/bench_fleet).
agv_add_test(test_fleet SOURCES test_fleet.cpp LIBS agv_sim agv_site LABELS unit site TIMEOUT 300)
