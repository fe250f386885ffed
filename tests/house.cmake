# The house's rules on the source tree (tests/house_check.py): functions at most 100 lines, no
# circle between src/'s files or directories (from what the library's object files call), nothing
# in src/transport calling into src/formfactor, no library message naming a command-line flag.
# What is not yet under the rules is listed in the script and may only shrink.
find_program(BN_PYTHON3 python3)
if(BN_PYTHON3)
  add_test(NAME house.rules COMMAND ${BN_PYTHON3} ${CMAKE_CURRENT_LIST_DIR}/house_check.py ${PROJECT_SOURCE_DIR}
    ${PROJECT_BINARY_DIR}/CMakeFiles/bounce.dir)
  set_tests_properties(house.rules PROPERTIES LABELS house TIMEOUT 120)
endif()
# The manual's relative links, and the README tour's cheap lines as written (tests/docs_check.py).
if(BN_PYTHON3 AND NOT BOUNCE_SANITIZE)
  add_test(NAME docs.links_and_tour COMMAND ${BN_PYTHON3} ${CMAKE_CURRENT_LIST_DIR}/docs_check.py ${PROJECT_SOURCE_DIR}
    $<TARGET_FILE:bounce_cli>)
  set_tests_properties(docs.links_and_tour PROPERTIES LABELS docs TIMEOUT 300)
endif()
