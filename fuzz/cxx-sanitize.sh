#!/bin/sh
# C++ compiler wrapper for fuzz builds (scripts/fuzz.sh sets CXX to this file). icrender's own
# C++ layer (cpp/*.cpp, which includes tinygltf and stb_image) is compiled with AddressSanitizer,
# UndefinedBehaviorSanitizer in trap mode (no runtime needed: a UB check executes an illegal
# instruction, which libFuzzer reports as a crash) and libFuzzer's coverage instrumentation, so
# the fuzzer is guided by, and checks, the C++ side as well as the Rust side. Everything else
# compiled with CXX (libFuzzer itself) is built unchanged.
for arg in "$@"; do
    case "$arg" in
        cpp/scene_io*.cpp | cpp/image_io.cpp | */cpp/scene_io*.cpp | */cpp/image_io.cpp)
            exec clang++ "$@" -fsanitize=address,fuzzer-no-link \
                -fsanitize=undefined -fsanitize-trap=undefined -fno-sanitize-recover=all \
                -fno-omit-frame-pointer -g
            ;;
    esac
done
exec clang++ "$@"
