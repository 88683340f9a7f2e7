# The raster -> mesh -> encode -> decode fuzzer (tests/fuzz/fuzz_mesh.cpp), for clang's
# libFuzzer. Included by the top-level CMakeLists.txt when TB_BUILD_FUZZ is ON; configure with
#   CXX=clang++-14 cmake -S . -B build-fuzz -DTB_BUILD_FUZZ=ON -DTB_BUILD_TESTS=OFF \
#       -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG="-g -O1"
# and run: build-fuzz/fuzz_mesh tests/fuzz/corpus/mesh -max_total_time=60
# The libraries it reaches (tb_core, tb_tiler) are instrumented for coverage and AddressSanitizer
# unless the whole build already is (sanitizer flags in CMAKE_CXX_FLAGS).
if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "fuzz_mesh needs clang (libFuzzer); configure with CXX=clang++-14")
endif()
if(NOT CMAKE_CXX_FLAGS MATCHES "fuzzer")
    foreach(target tb_core tb_tiler)
        target_compile_options(${target} PRIVATE -fsanitize=address,fuzzer-no-link)
    endforeach()
endif()
add_executable(fuzz_mesh ${CMAKE_SOURCE_DIR}/tests/fuzz/fuzz_mesh.cpp)
target_include_directories(fuzz_mesh PRIVATE ${CMAKE_SOURCE_DIR})
target_link_libraries(fuzz_mesh PRIVATE tb_tiler)
target_compile_options(fuzz_mesh PRIVATE -fsanitize=fuzzer,address)
target_link_options(fuzz_mesh PRIVATE -fsanitize=fuzzer,address)
tb_warnings(fuzz_mesh)
