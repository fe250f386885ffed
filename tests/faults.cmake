# Faults from outside (tests/faults.sh), in two parts: "files" (ulimit -f, a full and a read-only
# directory, ulimit -v at each stage in the normal build only) and "signals" (SIGTERM in meshing, the
# form factors, refinement and the gather).
foreach(part files signals)
  add_test(NAME faults.${part} COMMAND ${CMAKE_CURRENT_LIST_DIR}/faults.sh $<TARGET_FILE:bounce_cli>
    ${PROJECT_SOURCE_DIR} ${CMAKE_CURRENT_BINARY_DIR}/tmp/faults_${part} ${part} $<$<BOOL:${BOUNCE_SANITIZE}>:asan>)
  set_tests_properties(faults.${part} PROPERTIES LABELS faults TIMEOUT 300)
endforeach()
# The signals alone: their SIGTERM rows allow 5 s to stop. Beside other tests the sanitized gather once
# took more (alone it stops within 1.6 s), so the row timed the machine's load, not bounce.
set_tests_properties(faults.signals PROPERTIES RUN_SERIAL TRUE)
