# Installs the build tree into a temporary prefix, then configures, builds and runs the consumer
# project tests/package against it (find_package(geodrift REQUIRED) + geodrift::core).
# A broken export, a missing installed header or Find module fails here. CXX_FLAGS and
# LINKER_FLAGS (optional) are the build tree's: a sanitized build's static frontends need the
# consumer compiled and linked with the same -fsanitize flags.
foreach(v BUILD_DIR CONSUMER_SOURCE WORK_DIR CXX)
  if(NOT DEFINED ${v})
    message(FATAL_ERROR "RunPackageTest.cmake: ${v} not set")
  endif()
endforeach()
file(REMOVE_RECURSE ${WORK_DIR})
set(prefix ${WORK_DIR}/prefix)

function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
  message(STATUS "${out}")
endfunction()

run(${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${prefix})
run(${CMAKE_COMMAND} -S ${CONSUMER_SOURCE} -B ${WORK_DIR}/build -DCMAKE_PREFIX_PATH=${prefix}
    -DCMAKE_CXX_COMPILER=${CXX} -DCMAKE_BUILD_TYPE=Release "-DCMAKE_CXX_FLAGS=${CXX_FLAGS}"
    "-DCMAKE_EXE_LINKER_FLAGS=${LINKER_FLAGS}")
run(${CMAKE_COMMAND} --build ${WORK_DIR}/build)
run(${WORK_DIR}/build/consumer)
