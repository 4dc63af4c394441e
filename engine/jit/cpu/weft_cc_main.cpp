// weft-cc: the child process in which weftd compiles a module for the CPU when a compile time
// limit is set (engine/jit/cpu/compile_process.h). Not meant to be run by hand.
#include "engine/jit/cpu/compile_process.h"

int main(int argc, char** argv) { return weft::jit::CompilerChildMain(argc, argv); }
