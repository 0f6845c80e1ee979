# The repository stands on its own: no file refers to a design document or paper notes kept
# outside it, and every docs/<page>.md a file cites exists.
#   cmake -DSOURCE_DIR=<repository> -P self_contained.cmake
cmake_minimum_required(VERSION 3.21)
# A build tree is any folder with a CMakeCache.txt (build/, build-asan/, a user's own). It is
# never read: its files are not the repository's, and tests running beside this one create and
# delete files in it (CMake's try-compile scratch folders), so reading it races with them.
function(_collect_repository_files folder)
  file(GLOB _entries LIST_DIRECTORIES true "${folder}/*")  # dot files too
  foreach(_entry IN LISTS _entries)
    get_filename_component(_name "${_entry}" NAME)
    if(IS_DIRECTORY "${_entry}")
      # Symbolic links are not followed, as GLOB_RECURSE does not: a link to a parent would
      # never end.
      if(NOT _name STREQUAL ".git" AND NOT IS_SYMLINK "${_entry}"
         AND NOT EXISTS "${_entry}/CMakeCache.txt")
        _collect_repository_files("${_entry}")
      endif()
    elseif(_name MATCHES "\\.(hpp|cpp|md|cmake|txt|py|sh)$" OR _name STREQUAL ".clang-tidy")
      file(RELATIVE_PATH _relative "${SOURCE_DIR}" "${_entry}")
      set_property(GLOBAL APPEND PROPERTY _repository_files "${_relative}")
    endif()
  endforeach()
endfunction()
_collect_repository_files("${SOURCE_DIR}")
get_property(_files GLOBAL PROPERTY _repository_files)
# Spelled in pieces so that this file does not match itself.
set(_outside "DESI" "GN.md|DESI" "GN §|reference/pa" "per.md|\\.\\./sha" "red/")
string(CONCAT _outside_regex ${_outside})
set(_problems "")
set(_checked 0)
foreach(_file IN LISTS _files)
  math(EXPR _checked "${_checked} + 1")
  file(READ ${SOURCE_DIR}/${_file} _text)
  if(_text MATCHES "(${_outside_regex})")
    string(APPEND _problems "  ${_file}: refers to '${CMAKE_MATCH_1}', outside the repository\n")
  endif()
  string(REGEX MATCHALL "docs/[A-Za-z0-9_/.-]+\\.md" _cited "${_text}")
  list(REMOVE_DUPLICATES _cited)
  foreach(_page IN LISTS _cited)
    if(NOT EXISTS ${SOURCE_DIR}/${_page})
      string(APPEND _problems "  ${_file}: cites ${_page}, which does not exist\n")
    endif()
  endforeach()
endforeach()
if(_problems)
  message(FATAL_ERROR "files that are not self-contained:\n${_problems}")
endif()
message(STATUS "self-contained: ${_checked} files, every cited docs/ page exists")
