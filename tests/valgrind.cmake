# memcheck on one small solve through the CLI (scripts/valgrind.sh covers every subcommand).
# Not in the sanitized build (ASan and valgrind do not mix).
find_program(BN_VALGRIND valgrind)
if(BN_VALGRIND AND NOT BOUNCE_SANITIZE)
  add_test(NAME valgrind.solve_small
    COMMAND sh ${CMAKE_CURRENT_LIST_DIR}/valgrind_run.sh ${BN_VALGRIND} ${CMAKE_CURRENT_LIST_DIR}/valgrind.supp
      $<TARGET_FILE:bounce_cli> solve ${PROJECT_SOURCE_DIR}/meshes/cornell-box.obj --unit mm --patches 40 -n 2
      --threads 2 -q -o ${CMAKE_CURRENT_BINARY_DIR}/tmp/valgrind-patches.csv)
  set_tests_properties(valgrind.solve_small PROPERTIES LABELS valgrind TIMEOUT 300 SKIP_RETURN_CODE 77)
endif()
