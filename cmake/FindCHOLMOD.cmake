# FindCHOLMOD.cmake: CHOLMOD from SuiteSparse as the imported target SuiteSparse::CHOLMOD.
#
# Debian 12 ships SuiteSparse 5.12 without a CMake config or pkg-config file, so this module
# finds the header and the libraries CHOLMOD needs (cholmod, amd, camd, colamd, ccolamd,
# suitesparseconfig). Sets CHOLMOD_FOUND, CHOLMOD_INCLUDE_DIR, CHOLMOD_LIBRARIES, and creates
# SuiteSparse::CHOLMOD. On failure the message names the missing piece and the Debian package.

find_path(CHOLMOD_INCLUDE_DIR cholmod.h PATH_SUFFIXES suitesparse)
set(_cholmod_missing "")
set(CHOLMOD_LIBRARIES "")
foreach(_lib cholmod amd camd colamd ccolamd suitesparseconfig)
  find_library(CHOLMOD_${_lib}_LIBRARY NAMES ${_lib})
  mark_as_advanced(CHOLMOD_${_lib}_LIBRARY)
  if(CHOLMOD_${_lib}_LIBRARY)
    list(APPEND CHOLMOD_LIBRARIES ${CHOLMOD_${_lib}_LIBRARY})
  else()
    list(APPEND _cholmod_missing lib${_lib})
  endif()
endforeach()
if(NOT CHOLMOD_INCLUDE_DIR)
  list(APPEND _cholmod_missing "cholmod.h")
endif()

include(FindPackageHandleStandardArgs)
if(_cholmod_missing)
  set(_cholmod_reason "missing ${_cholmod_missing}; on Debian/Ubuntu: apt-get install libsuitesparse-dev")
endif()
find_package_handle_standard_args(CHOLMOD
  REQUIRED_VARS CHOLMOD_INCLUDE_DIR CHOLMOD_cholmod_LIBRARY CHOLMOD_amd_LIBRARY
                CHOLMOD_suitesparseconfig_LIBRARY
  REASON_FAILURE_MESSAGE "${_cholmod_reason}")
mark_as_advanced(CHOLMOD_INCLUDE_DIR)

if(CHOLMOD_FOUND AND NOT TARGET SuiteSparse::CHOLMOD)
  add_library(SuiteSparse::CHOLMOD UNKNOWN IMPORTED)
  list(GET CHOLMOD_LIBRARIES 0 _cholmod_main)
  list(SUBLIST CHOLMOD_LIBRARIES 1 -1 _cholmod_deps)
  set_target_properties(SuiteSparse::CHOLMOD PROPERTIES
    IMPORTED_LOCATION "${_cholmod_main}"
    INTERFACE_INCLUDE_DIRECTORIES "${CHOLMOD_INCLUDE_DIR}"
    INTERFACE_LINK_LIBRARIES "${_cholmod_deps}")
endif()
unset(_cholmod_missing)
unset(_cholmod_reason)
