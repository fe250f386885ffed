# The Python package (python/bounce, ctypes over libbounce.so): pytest under Debian's python3
# (tests/python/run.sh skips when numpy or pytest is missing). Not in the sanitized build: an
# uninstrumented python cannot load an ASan-instrumented library.
if(NOT BOUNCE_SANITIZE)
  add_test(NAME python.pytest COMMAND ${CMAKE_CURRENT_LIST_DIR}/python/run.sh $<TARGET_FILE:bounce>
    $<TARGET_FILE:bounce_cli> ${PROJECT_SOURCE_DIR})
  set_tests_properties(python.pytest PROPERTIES LABELS python TIMEOUT 600 SKIP_RETURN_CODE 77)
endif()
