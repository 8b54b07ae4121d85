# The FBKSD CMake package, as installed by deploy/install-sdk.sh:
#   <prefix>/lib/cmake/fbksd/fbksdConfig.cmake  (this file)
#   <prefix>/lib/libfbksd.so                    (the C library)
#   <prefix>/include/fbksd/...                  (C and C++ headers)
#
# A technique's CMakeLists.txt needs only:
#   find_package(fbksd REQUIRED)
#   target_link_libraries(my-technique fbksd::client)
# Renderers link fbksd::renderer, metric programs fbksd::iqa (one library,
# three names, as in the original package). 2.x-era OpenEXR names: below.
get_filename_component(_fbksd_prefix "${CMAKE_CURRENT_LIST_DIR}/../../.." ABSOLUTE)
if(NOT EXISTS "${_fbksd_prefix}/lib/libfbksd.so")
    set(fbksd_FOUND FALSE)
    set(fbksd_NOT_FOUND_MESSAGE "${_fbksd_prefix}/lib/libfbksd.so is missing: reinstall with deploy/install-sdk.sh")
    return()
endif()
include(CMakeFindDependencyMacro)
find_dependency(Threads)
foreach(_fbksd_target client renderer iqa)
    if(NOT TARGET fbksd::${_fbksd_target})
        add_library(fbksd::${_fbksd_target} SHARED IMPORTED)
        set_target_properties(fbksd::${_fbksd_target} PROPERTIES
            IMPORTED_LOCATION "${_fbksd_prefix}/lib/libfbksd.so"
            INTERFACE_INCLUDE_DIRECTORIES "${_fbksd_prefix}/include"
            INTERFACE_LINK_LIBRARIES Threads::Threads
            INTERFACE_COMPILE_FEATURES cxx_std_14)
    endif()
endforeach()

# Build files written for FBKSD 2.x link OpenEXR 2 by its library names
# (IlmImf, Half, Iex, IlmThread, Imath) and add only /usr/include/OpenEXR;
# OpenEXR 3 renamed its libraries and moved Imath (half.h, ImathVec.h, ...)
# to a directory of its own. Where OpenEXR 3 is installed, those names are
# targets here that link it with both include directories, so such build
# files work unchanged. Names a project already defines are left alone.
find_package(OpenEXR CONFIG QUIET)
if(OpenEXR_FOUND)
    foreach(_fbksd_name IlmImf IlmImfUtil Half Iex IlmThread Imath)
        if(NOT TARGET ${_fbksd_name})
            add_library(${_fbksd_name} INTERFACE IMPORTED)
            set_target_properties(${_fbksd_name} PROPERTIES
                INTERFACE_LINK_LIBRARIES "OpenEXR::OpenEXR;OpenEXR::OpenEXRUtil;Imath::Imath")
        endif()
    endforeach()
endif()
set(fbksd_FOUND TRUE)
