# The route planner (docs/design/site_planner.md): hand-made degenerate sites, random sites
# against an independent shortest path, the drivable trajectory, the VDA 5050 order.
agv_add_test(test_planner SOURCES test_planner.cpp test_planner_random.cpp
             LIBS agv_site LABELS unit site TIMEOUT 120)
