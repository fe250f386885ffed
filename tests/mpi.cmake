# bounce under mpirun (BOUNCE_MPI): one process's bits from 1, 2 and 4 processes (tests/mpi_check.sh).
# Under the sanitizers (BOUNCE_SANITIZE) the same checks at -np 2 on small settings
# (BN_TEST_SANITIZED=1), with OpenMPI's own allocations suppressed for LeakSanitizer (tests/lsan.supp).
if(BOUNCE_MPI)
  add_test(NAME mpi.identical_to_one_process COMMAND ${CMAKE_CURRENT_LIST_DIR}/mpi_check.sh $<TARGET_FILE:bounce_cli>
    ${PROJECT_SOURCE_DIR} ${CMAKE_CURRENT_BINARY_DIR}/tmp/mpi_check)
  set_tests_properties(mpi.identical_to_one_process PROPERTIES LABELS mpi TIMEOUT 900 SKIP_RETURN_CODE 77)
  if(BOUNCE_SANITIZE)
    # identity checks only (no kill or interrupt rows, whose timing wants the machine to itself): beside
    # the other tests, started early (17 s alone, most of it LeakSanitizer's slow unwinding in the ranks
    # whose leaks are looked for: tests/mpi_check.sh says which)
    set_tests_properties(mpi.identical_to_one_process PROPERTIES ENVIRONMENT "BN_TEST_SANITIZED=1" COST 30)
  else()
    set_tests_properties(mpi.identical_to_one_process PROPERTIES RUN_SERIAL TRUE)
  endif()
endif()
# bn_dist_agree: the lowest failing rank's status on every rank (tests/mpi_agree.c).
if(BOUNCE_MPI)
  add_executable(mpi_agree ${CMAKE_CURRENT_LIST_DIR}/mpi_agree.c)
  target_link_libraries(mpi_agree PRIVATE bounce)
  add_test(NAME mpi.agree_lowest_failing_rank COMMAND ${CMAKE_CURRENT_LIST_DIR}/mpi_agree.sh $<TARGET_FILE:mpi_agree>)
  set_tests_properties(mpi.agree_lowest_failing_rank PROPERTIES LABELS mpi TIMEOUT 120 SKIP_RETURN_CODE 77)
endif()
