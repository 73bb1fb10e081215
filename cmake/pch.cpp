// The translation unit that precompiles a header set (CMakeLists.txt: penumbra_pch): the
// targets that reuse it get the headers from the precompiled file.
