# Test registration for geodrift (Catch2 2.13 through CTest).
#
# geodrift_add_catch_tests(<name> SOURCES ... [LIBS ...]) builds one test executable and
# registers its test cases with CTest, with labels taken from Catch tags explicitly (Catch2 2.13
# does not do it):
#   - [data] cases (they read GEODRIFT_DATA_DIR): label "data"; when the data directory was
#     not found at configure time they are registered as ONE test that CTest reports as skipped
#     (exit code 77 + SKIP_RETURN_CODE), never as passed;
#   - [slow] cases: label "slow" (they shrink themselves when CI=true or GEODRIFT_REDUCED=1);
#   - everything else: label "fast".
include(Catch)

function(geodrift_add_catch_tests name)
  cmake_parse_arguments(ARG "" "" "SOURCES;LIBS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE geodrift_catch_main geodrift_test_support ${ARG_LIBS})
  geodrift_target_defaults(${name})
  geodrift_test_flags(${name})
  catch_discover_tests(${name} TEST_SPEC "~[slow]~[data]" TEST_PREFIX "${name}: "
    PROPERTIES LABELS "fast")
  catch_discover_tests(${name} TEST_SPEC "[slow]~[data]" TEST_PREFIX "${name}: "
    PROPERTIES LABELS "slow")
  if(GEODRIFT_HAVE_DATA)
    catch_discover_tests(${name} TEST_SPEC "[data]" TEST_PREFIX "${name}: "
      PROPERTIES LABELS "data")
  else()
    add_test(NAME ${name}_data_skipped
      COMMAND sh -c "echo 'skipped: ${GEODRIFT_DATA_DIR} not found (set -DGEODRIFT_DATA_DIR)'; exit 77")
    set_tests_properties(${name}_data_skipped PROPERTIES
      SKIP_RETURN_CODE 77 LABELS "data")
  endif()
endfunction()

# Sanitizer flags for test code (GEODRIFT_SANITIZE=ON): ASan + UBSan, no recovery, so a finding
# fails the test.
function(geodrift_test_flags target)
  target_compile_definitions(${target} PRIVATE GEODRIFT_ENABLE_ASSERTS)
  if(GEODRIFT_SANITIZE)
    target_compile_options(${target} PRIVATE -fsanitize=address,undefined
      -fno-sanitize-recover=all -fno-omit-frame-pointer)
    target_link_options(${target} PRIVATE -fsanitize=address,undefined)
  endif()
endfunction()
