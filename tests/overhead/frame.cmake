# The per-frame pipeline (algo/src/overhead/camera_frame.cpp): rendered frames of one camera over
# three vehicles and a stranger's tag; and the smoke run of eval_overhead (tools/eval/overhead) on
# tiny settings, where the evaluation programs are built.
agv_add_test(test_camera_frame SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_camera_frame.cpp
             LIBS agv_overhead agv_sim LABELS unit overhead TIMEOUT 120)
if(TARGET eval_overhead)
  add_test(NAME eval_overhead_smoke
           COMMAND eval_overhead --site-mm 5000 --cameras 1 --width 960 --height 540 --tag-px 24
                   --agvs 3 --duration-s 2 --fps 10 --seed 2)
  set_tests_properties(eval_overhead_smoke PROPERTIES LABELS "overhead" TIMEOUT 20
                       PASS_REGULAR_EXPRESSION "identity: wrong-id fixes 0 ")
  # Parcels loaded during the run over every tag: the covered ticks are scored apart.
  add_test(NAME eval_overhead_parcels_smoke
           COMMAND eval_overhead --site-mm 5000 --cameras 1 --width 960 --height 540 --tag-px 24
                   --agvs 3 --duration-s 3 --fps 10 --seed 2 --parcels 1 --load-from-s 1
                   --cover-tags)
  set_tests_properties(eval_overhead_parcels_smoke PROPERTIES LABELS "overhead" TIMEOUT 30
                       PASS_REGULAR_EXPRESSION "tags under a parcel: [1-9][0-9]* ticks")
  # The cameras as the desk's ceiling calibration solves them from rendered surveyed tags, the
  # survey 1 mm off: solved on every tag, and the fleet's p95 under 10 mm with no wrong id.
  if(TARGET agv_desk)
    add_test(NAME eval_overhead_calibrated_smoke
             COMMAND eval_overhead --site-mm 5000 --cameras 1 --width 960 --height 540
                     --tag-px 24 --agvs 3 --duration-s 2 --fps 10 --seed 2 --calibrate-tags 8
                     --survey-error-mm 1)
    set_tests_properties(eval_overhead_calibrated_smoke PROPERTIES LABELS "overhead" TIMEOUT 30
                         PASS_REGULAR_EXPRESSION "calibrated from 8 tags \\(0 rejected\\)"
                         FAIL_REGULAR_EXPRESSION
                         "wrong-id fixes [1-9];position error p50 [0-9.]+ mm, p95 [1-9][0-9]+\\.")
  endif()
endif()
