# One warnings/options function for every hpds target.
function(hpds_set_options target)
  target_compile_features(${target} PUBLIC cxx_std_17)
  if(CMAKE_CXX_COMPILER_ID MATCHES "GNU|Clang")
    target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow=local -Wno-unused-parameter)
  endif()
  # The libraries are shared and built with -fPIC, so GCC assumes any exported function may be interposed at load
  # time and neither inlines it nor calls it directly, even inside its own file. hpds never relies on interposition.
  if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
    target_compile_options(${target} PRIVATE -fno-semantic-interposition)
  endif()
endfunction()

# AddressSanitizer + UndefinedBehaviorSanitizer for every target of the build (`make test-sanitize`). Global rather
# than per target because static libraries and the executables linking them must agree. UB is made fatal here so a
# report fails its test even when UBSAN_OPTIONS is not set.
option(HPDS_SANITIZE "Build with -fsanitize=address,undefined (own build directory)" OFF)
if(HPDS_SANITIZE)
  add_compile_options(-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer)
  add_link_options(-fsanitize=address,undefined)
  # For tests whose host program is uninstrumented (Debian's nodelet manager, python3) but loads our instrumented
  # code: the runtimes must come first, and the host's own allocations, never freed at exit, are not our leaks.
  execute_process(COMMAND ${CMAKE_CXX_COMPILER} -print-file-name=libasan.so OUTPUT_VARIABLE HPDS_LIBASAN
                  OUTPUT_STRIP_TRAILING_WHITESPACE)
  execute_process(COMMAND ${CMAKE_CXX_COMPILER} -print-file-name=libubsan.so OUTPUT_VARIABLE HPDS_LIBUBSAN
                  OUTPUT_STRIP_TRAILING_WHITESPACE)
  set(HPDS_SANITIZER_PRELOAD_ENV "LD_PRELOAD=${HPDS_LIBASAN}:${HPDS_LIBUBSAN};ASAN_OPTIONS=detect_leaks=0")
endif()

# ThreadSanitizer (`make test-tsan`): the core's threads (the pipeline's second thread during insertion, the parallel
# normals, the tiled builds) under the core tests. Not with HPDS_SANITIZE: the two runtimes exclude each other.
option(HPDS_TSAN "Build with -fsanitize=thread (own build directory)" OFF)
if(HPDS_TSAN)
  if(HPDS_SANITIZE)
    message(FATAL_ERROR "HPDS_TSAN and HPDS_SANITIZE cannot be combined: build them in separate directories")
  endif()
  add_compile_options(-fsanitize=thread -fno-omit-frame-pointer)
  add_link_options(-fsanitize=thread)
endif()
