# The route planner (docs/design/site_planner.md): hand-made degenerate sites, random sites
# against an independent shortest path, the drivable trajectory, the VDA 5050 order.
agv_add_test(test_planner SOURCES test_planner.cpp test_planner_random.cpp
             test_planner_trajectory.cpp LIBS agv_site LABELS unit site TIMEOUT 120)
agv_add_test(test_order SOURCES test_order.cpp LIBS agv_site agv_vda5050 LABELS unit site)
if(TARGET test_order)
  find_program(AGV_ORDER_PYTHON3 python3 PATHS /usr/bin NO_DEFAULT_PATH)
  add_test(NAME vda5050_order_schema
           COMMAND ${AGV_ORDER_PYTHON3} ${CMAKE_CURRENT_SOURCE_DIR}/test_order_schema.py
                   $<TARGET_FILE:test_order>
                   ${PROJECT_SOURCE_DIR}/tests/vda5050/schemas/2.1.0/order.schema
                   ${CMAKE_CURRENT_BINARY_DIR}/order_example.json)
  set_tests_properties(vda5050_order_schema PROPERTIES LABELS "unit;site" TIMEOUT 60)
endif()
