# The repository stands on its own: no file refers to a design document or paper notes kept
# outside it, and every docs/<page>.md a file cites exists.
#   cmake -DSOURCE_DIR=<repository> -P self_contained.cmake
cmake_minimum_required(VERSION 3.21)
file(GLOB_RECURSE _files RELATIVE ${SOURCE_DIR}
     ${SOURCE_DIR}/*.hpp ${SOURCE_DIR}/*.cpp ${SOURCE_DIR}/*.md ${SOURCE_DIR}/*.cmake
     ${SOURCE_DIR}/*.txt ${SOURCE_DIR}/*.py ${SOURCE_DIR}/*.sh ${SOURCE_DIR}/.clang-tidy)
# Spelled in pieces so that this file does not match itself.
set(_outside "DESI" "GN.md|DESI" "GN §|reference/pa" "per.md|\\.\\./sha" "red/")
string(CONCAT _outside_regex ${_outside})
set(_problems "")
set(_checked 0)
foreach(_file IN LISTS _files)
  if(_file MATCHES "^(build|\\.git)/" OR _file MATCHES "/build/")
    continue()
  endif()
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
