# Helpers shared by the per-folder CMakeLists.

# Warnings for our own code only (third-party headers are system headers).
function(flarekit_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic)
endfunction()

# flarekit_library(<layer> SOURCES ... DEPS ...): the static library flarekit_<layer>, whose public
# headers live at the folder's top and are included as "<layer>/<header>.h".
function(flarekit_library layer)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_library(flarekit_${layer} STATIC ${ARG_SOURCES})
  target_include_directories(flarekit_${layer} PUBLIC ${PROJECT_SOURCE_DIR})
  target_link_libraries(flarekit_${layer} PUBLIC ${ARG_DEPS})
  flarekit_warnings(flarekit_${layer})
endfunction()

# flarekit_tests(<name> SOURCES ... DEPS ... [LABELS ...]): one GoogleTest binary registered in
# CTest test by test. Tests find fixtures through FLAREKIT_SOURCE_DIR and the CLI through
# FLAREKIT_BINARY.
function(flarekit_tests name)
  if(NOT FLAREKIT_BUILD_TESTS)
    return()
  endif()
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS;LABELS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main GTest::gmock)
  target_compile_definitions(${name} PRIVATE
    FLAREKIT_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    FLAREKIT_BINARY="${CMAKE_RUNTIME_OUTPUT_DIRECTORY}/flarekit")
  flarekit_warnings(${name})
  set(labels unit)
  if(ARG_LABELS)
    set(labels ${ARG_LABELS})
  endif()
  gtest_discover_tests(${name}
    DISCOVERY_TIMEOUT 120
    TEST_LIST ${name}_TESTS
    PROPERTIES ENVIRONMENT "ASAN_OPTIONS=detect_leaks=1:verify_asan_link_order=0")
  # Labels are set once the tests are discovered: CMake 3.25 splits a list given in PROPERTIES,
  # so only the first of several labels would stick.
  set(label_file ${CMAKE_CURRENT_BINARY_DIR}/${name}_labels.cmake)
  file(WRITE ${label_file}
    "if(${name}_TESTS)\n  set_tests_properties(\${${name}_TESTS} PROPERTIES LABELS \"${labels}\")\nendif()\n")
  set_property(DIRECTORY APPEND PROPERTY TEST_INCLUDE_FILES ${label_file})
endfunction()
