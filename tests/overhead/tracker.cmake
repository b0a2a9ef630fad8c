# The per-vehicle EKF (algo/src/overhead/tracker*.cpp): synthetic fixes, no rendering. The binary
# counts heap allocations (it replaces the global operator new).
agv_add_test(test_tracker SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_tracker.cpp
             ${CMAKE_SOURCE_DIR}/tests/support/alloc_counter.cpp LIBS agv_overhead
             LABELS unit overhead)
# The search windows (algo/src/overhead/search.cpp): synthetic tracks; one tiny rendered frame
# checks the predicted corners against the renderer's truth.
agv_add_test(test_search SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_search.cpp
             LIBS agv_overhead agv_sim LABELS unit overhead)
# The tracker on the simulated fleet's motion: turns on the spot that start and stop in a step,
# fixes as precise as a 60 px tag's (synthetic).
agv_add_test(test_tracker_turns SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_tracker_turns.cpp
             LIBS agv_overhead LABELS unit overhead)
# The route prior (algo/src/overhead/route_prior.cpp, FleetTracker::set_route): a coasting track
# extrapolated along its vehicle's route round a corner; synthetic fixes.
agv_add_test(test_route_prior SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_route_prior.cpp
             LIBS agv_overhead agv_vda5050 LABELS unit overhead)
# Orders as routes (algo/src/overhead/order_intake.cpp): VDA 5050 orders for fleet vehicles,
# stitched updates, and every refusal named.
agv_add_test(test_order_intake SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_order_intake.cpp
             LIBS agv_overhead LABELS unit overhead)
