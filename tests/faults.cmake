# Faults from outside (tests/faults.sh): ulimit -f, a full and a read-only directory, ulimit -v at
# each stage (normal build only), SIGTERM in meshing, refinement and the gather.
add_test(NAME faults.outside COMMAND ${CMAKE_CURRENT_LIST_DIR}/faults.sh $<TARGET_FILE:bounce_cli>
  ${PROJECT_SOURCE_DIR} ${CMAKE_CURRENT_BINARY_DIR}/tmp/faults $<$<BOOL:${BOUNCE_SANITIZE}>:asan>)
# Beside the other tests, started early: its SIGTERM rows stop within 1.6 s under the sanitizers (5 s
# allowed), and a slower run only keeps each command in its stage longer when the signal comes.
set_tests_properties(faults.outside PROPERTIES LABELS faults TIMEOUT 300 COST 30)
