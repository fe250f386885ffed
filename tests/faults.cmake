# Faults from outside (tests/faults.sh): ulimit -f, a full and a read-only directory, ulimit -v at
# each stage (normal build only), SIGTERM in meshing, refinement and the gather.
add_test(NAME faults.outside COMMAND ${CMAKE_CURRENT_LIST_DIR}/faults.sh $<TARGET_FILE:bounce_cli>
  ${PROJECT_SOURCE_DIR} ${CMAKE_CURRENT_BINARY_DIR}/tmp/faults $<$<BOOL:${BOUNCE_SANITIZE}>:asan>)
# Alone: its SIGTERM rows allow 5 s to stop. Beside other tests the sanitized gather once took more
# (alone it stops within 1.6 s), so the row timed the machine's load, not bounce.
set_tests_properties(faults.outside PROPERTIES LABELS faults TIMEOUT 300 RUN_SERIAL TRUE)
