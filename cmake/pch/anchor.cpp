// Compiled only to build the precompiled header of cmake/ArnavPch.cmake (the headers come
// in through CMake's forced include); the object is linked into nothing.
