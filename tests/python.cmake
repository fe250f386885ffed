# The Python package (python/bounce, ctypes over libbounce.so): pytest against the package installed
# with pip into a venv (tests/python/run.sh; skipped when numpy, pytest or venv is missing), and mypy
# on its sources (skipped without Debian's mypy). Not in the sanitized build: an uninstrumented python
# cannot load an ASan-instrumented library.
if(NOT BOUNCE_SANITIZE)
  add_test(NAME python.pytest COMMAND ${CMAKE_CURRENT_LIST_DIR}/python/run.sh $<TARGET_FILE:bounce>
    $<TARGET_FILE:bounce_cli> ${PROJECT_SOURCE_DIR} ${CMAKE_COMMAND})
  set_tests_properties(python.pytest PROPERTIES LABELS python TIMEOUT 600 SKIP_RETURN_CODE 77)
  add_test(NAME python.mypy COMMAND sh -c "command -v mypy >/dev/null || { echo 'SKIP: no mypy (scripts/setup.sh installs Debian mypy)'; exit 77; }; mypy --no-incremental --cache-dir=/dev/null \"$1\"" sh ${PROJECT_SOURCE_DIR}/python/bounce)
  set_tests_properties(python.mypy PROPERTIES LABELS python TIMEOUT 300 SKIP_RETURN_CODE 77)
endif()
