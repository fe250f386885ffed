# The installed tree works for another C program (find_package and pkg-config). Not in the
# sanitized build: an uninstrumented consumer cannot load an ASan-instrumented library.
if(NOT BOUNCE_SANITIZE)
  configure_file(${CMAKE_CURRENT_LIST_DIR}/install_consumer.cmake.in ${CMAKE_CURRENT_BINARY_DIR}/install_consumer.cmake @ONLY)
  add_test(NAME install.consumer COMMAND ${CMAKE_COMMAND} -P ${CMAKE_CURRENT_BINARY_DIR}/install_consumer.cmake)
  set_tests_properties(install.consumer PROPERTIES TIMEOUT 300 LABELS install)
endif()
