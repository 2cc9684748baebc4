# CTest script (tests/CMakeLists.txt: consumer_package): installs the devel component of the build
# tree into a fresh prefix, moves that prefix (the package must be relocatable), configures and builds
# tests/consumer against the moved prefix with find_package(contactgrid), and runs its app.
#   cmake -DBUILD=<build tree> -DSOURCE=<tests/consumer> -DWORK=<scratch> -DGENERATOR=<gen>
#         -DCXX=<compiler> -DVERSION=<project version> -P check_package.cmake
function(step)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
  message(STATUS "ok: ${ARGN}\n${out}")
endfunction()

file(REMOVE_RECURSE ${WORK})
step(${CMAKE_COMMAND} --install ${BUILD} --prefix ${WORK}/installed --component devel)
file(RENAME ${WORK}/installed ${WORK}/moved)
if(NOT EXISTS ${WORK}/moved/include/contactgrid/engine.hpp)
  message(FATAL_ERROR "include/contactgrid/engine.hpp not installed")
endif()
step(${CMAKE_COMMAND} -S ${SOURCE} -B ${WORK}/build -G ${GENERATOR} -DCMAKE_CXX_COMPILER=${CXX}
     -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH=${WORK}/moved -DEXPECTED_VERSION=${VERSION})
step(${CMAKE_COMMAND} --build ${WORK}/build)
step(${WORK}/build/app)
