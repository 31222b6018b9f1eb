#pragma once

/// geodrift version. CMake reads the project version from this file, so it is the single source.
#define GEODRIFT_VERSION_MAJOR 0
#define GEODRIFT_VERSION_MINOR 1
#define GEODRIFT_VERSION_PATCH 0
#define GEODRIFT_VERSION_STRING "0.1.0"

namespace geodrift {
/// The library version as "major.minor.patch"; written into every output file's header.
inline constexpr const char* kVersion = GEODRIFT_VERSION_STRING;
}  // namespace geodrift
