# The package test (tests/api/CMakeLists.txt): install, find_package from a fresh project, run.
#   cmake -DBUILD_DIR=... -DEXAMPLES_DIR=... -DWORK_DIR=... [-DGENERATOR=...] [-DCXX_COMPILER=...]
#         [-DBUILD_TYPE=...] [-DCXX_FLAGS=...] -P package_test.cmake
foreach(v BUILD_DIR EXAMPLES_DIR WORK_DIR)
  if(NOT DEFINED ${v})
    message(FATAL_ERROR "package_test.cmake: -D${v}=... is required")
  endif()
endforeach()

set(prefix ${WORK_DIR}/prefix)
set(example_build ${WORK_DIR}/examples-build)
file(REMOVE_RECURSE ${WORK_DIR})
file(MAKE_DIRECTORY ${WORK_DIR})

function(run what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  message(STATUS "${what}:\n${out}${err}")
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${what} failed (exit ${rc})")
  endif()
endfunction()

# 1. Install only the library's component (the CLI and anything else stay out).
run("install" ${CMAKE_COMMAND} --install ${BUILD_DIR} --component sandpatch_dev --prefix ${prefix})

# 2. The package holds the library, the public headers and the CMake files, and nothing of the
#    internal libraries or their headers.
file(GLOB_RECURSE installed RELATIVE ${prefix} ${prefix}/*)
list(SORT installed)
string(REPLACE ";" "\n  " listing "${installed}")
message(STATUS "installed:\n  ${listing}")
# (lib/ or lib/<multiarch>/, as GNUInstallDirs chose for the configured prefix)
set(libdir "lib[^/]*(/[^/]+)?")
foreach(required "^include/sandpatch/sandpatch\\.hpp$" "^include/sandpatch/bullet\\.hpp$"
        "^${libdir}/libsandpatch\\.so$" "^${libdir}/cmake/Sandpatch/SandpatchConfig\\.cmake$"
        "^${libdir}/cmake/Sandpatch/SandpatchConfigVersion\\.cmake$" "^${libdir}/cmake/Sandpatch/SandpatchTargets\\.cmake$")
  set(found FALSE)
  foreach(f ${installed})
    if(f MATCHES "${required}")
      set(found TRUE)
    endif()
  endforeach()
  if(NOT found)
    message(FATAL_ERROR "the package lacks a file matching ${required}")
  endif()
endforeach()
foreach(f ${installed})
  if(f MATCHES "\\.a$" OR (f MATCHES "^include/" AND NOT f MATCHES "^include/sandpatch/[a-z_]+\\.hpp$"))
    message(FATAL_ERROR "an internal file is installed: ${f}")
  endif()
endforeach()
file(GLOB headers ${prefix}/include/sandpatch/*.hpp)
foreach(h ${headers})
  file(STRINGS ${h} includes REGEX "^#include")
  foreach(line ${includes})
    if(NOT line MATCHES "^#include <")
      message(FATAL_ERROR "${h}: public headers include only <...> headers: ${line}")
    endif()
    if(line MATCHES "Eigen|nlohmann|btBullet|bullet|LinearMath" AND NOT h MATCHES "bullet\\.hpp$")
      message(FATAL_ERROR "${h}: a public header includes a dependency: ${line}")
    endif()
  endforeach()
endforeach()

# 3. A fresh project that knows nothing but the prefix.
set(gen_args)
if(GENERATOR)
  list(APPEND gen_args -G ${GENERATOR})
endif()
if(CXX_COMPILER)
  list(APPEND gen_args -DCMAKE_CXX_COMPILER=${CXX_COMPILER})
endif()
if(CXX_FLAGS)
  list(APPEND gen_args "-DCMAKE_CXX_FLAGS=${CXX_FLAGS}")
endif()
if(NOT BUILD_TYPE)
  set(BUILD_TYPE Release)
endif()
run("configure examples" ${CMAKE_COMMAND} -S ${EXAMPLES_DIR} -B ${example_build} ${gen_args}
    -DCMAKE_BUILD_TYPE=${BUILD_TYPE} -DCMAKE_PREFIX_PATH=${prefix})
run("build examples" ${CMAKE_COMMAND} --build ${example_build})

# 4. The example game runs and ends with the barrel on the terrain (exit code 0).
run("drop_barrel" ${example_build}/drop_barrel/drop_barrel 2)
