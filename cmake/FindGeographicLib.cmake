# FindGeographicLib.cmake: GeographicLib as the imported target GeographicLib::GeographicLib.
#
# Debian 12's own FindGeographicLib.cmake (in /usr/share/cmake/geographiclib) defines variables
# only; this module defines the target. Sets GeographicLib_FOUND, GeographicLib_INCLUDE_DIRS,
# GeographicLib_LIBRARIES.

find_path(GeographicLib_INCLUDE_DIR GeographicLib/Config.h)
find_library(GeographicLib_LIBRARY NAMES GeographicLib)
mark_as_advanced(GeographicLib_INCLUDE_DIR GeographicLib_LIBRARY)

include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(GeographicLib
  REQUIRED_VARS GeographicLib_LIBRARY GeographicLib_INCLUDE_DIR
  REASON_FAILURE_MESSAGE "on Debian/Ubuntu: apt-get install libgeographiclib-dev")

if(GeographicLib_FOUND)
  set(GeographicLib_INCLUDE_DIRS "${GeographicLib_INCLUDE_DIR}")
  set(GeographicLib_LIBRARIES "${GeographicLib_LIBRARY}")
  if(NOT TARGET GeographicLib::GeographicLib)
    add_library(GeographicLib::GeographicLib UNKNOWN IMPORTED)
    set_target_properties(GeographicLib::GeographicLib PROPERTIES
      IMPORTED_LOCATION "${GeographicLib_LIBRARY}"
      INTERFACE_INCLUDE_DIRECTORIES "${GeographicLib_INCLUDE_DIR}")
  endif()
endif()
