# Interface targets that carry the project's warning and sanitizer flags.
add_library(pmsc_warnings INTERFACE)
target_compile_options(pmsc_warnings INTERFACE -Wall -Wextra -Wpedantic -Wno-unused-parameter)
# GCC 12 reports hundreds of "'__Y' may be used uninitialized" from its own AVX-512 intrinsics
# headers (_mm512_undefined_pd) as Eigen inlines them at -march=native: a known false positive
# that buried real warnings in the build log. -Wuninitialized (definite cases) stays on.
target_compile_options(pmsc_warnings INTERFACE $<$<CXX_COMPILER_ID:GNU>:-Wno-maybe-uninitialized>)
# A unity batch #includes each .cpp, so GCC takes a class that uses its file's anonymous-namespace
# types (an engine's Impl, a test fixture's tests) for one declared in a header and warns for every
# field and base: a false positive there, where each .cpp's anonymous namespace is still its own.
if(PMSC_UNITY_BUILD)
  target_compile_options(pmsc_warnings INTERFACE $<$<CXX_COMPILER_ID:GNU>:-Wno-subobject-linkage>)
endif()

add_library(pmsc_sanitize INTERFACE)
if(PMSC_SANITIZE)
  # Line tables for the reports' stacks (-g1) where the build type carries no debug information of
  # its own; Debug and RelWithDebInfo keep theirs.
  target_compile_options(pmsc_sanitize INTERFACE -fsanitize=${PMSC_SANITIZE} -fno-omit-frame-pointer
                                                 $<$<NOT:$<CONFIG:Debug,RelWithDebInfo>>:-g1>)
  # With sanitizers GCC 12 turns the AVX-512 intrinsics' self-initialised placeholder
  # (`__m512d __Y = __Y;` in _mm512_undefined_pd) into dozens of "'__Y' is used uninitialized"
  # warnings per Eigen TU. The Release build keeps -Wuninitialized and is clean.
  target_compile_options(pmsc_sanitize INTERFACE $<$<CXX_COMPILER_ID:GNU>:-Wno-uninitialized>)
  target_link_options(pmsc_sanitize INTERFACE -fsanitize=${PMSC_SANITIZE})
  if(PMSC_SANITIZE MATCHES "undefined")
    target_compile_options(pmsc_sanitize INTERFACE -fno-sanitize-recover=undefined)
  endif()
endif()
install(TARGETS pmsc_warnings pmsc_sanitize EXPORT pmscTargets)

# pmsc_add_library(NAME pmsc_core ALIAS core SOURCES ... LINK ...): a static library with the
# project's flags, exported as pmsc::<ALIAS>, headers installed under include/<folder>/.
function(pmsc_add_library)
  cmake_parse_arguments(A "" "NAME;ALIAS;HEADER_DIR" "SOURCES;HEADERS;LINK" ${ARGN})
  add_library(${A_NAME} STATIC ${A_SOURCES})
  add_library(pmsc::${A_ALIAS} ALIAS ${A_NAME})
  set_target_properties(${A_NAME} PROPERTIES EXPORT_NAME ${A_ALIAS})
  target_include_directories(${A_NAME} PUBLIC
    $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}> $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
  target_link_libraries(${A_NAME} PUBLIC ${A_LINK} PRIVATE $<BUILD_INTERFACE:pmsc_warnings>)
  target_link_libraries(${A_NAME} PUBLIC $<BUILD_INTERFACE:pmsc_sanitize>)
  install(TARGETS ${A_NAME} EXPORT pmscTargets ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
  install(FILES ${A_HEADERS} DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/${A_HEADER_DIR})
endfunction()
