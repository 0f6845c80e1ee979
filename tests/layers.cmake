# The layer rule of docs/design.md, checked on every header under INCLUDE_DIR/sbptt/:
#
#   core  ←  nn, sim, optim  ←  bptt  ←  objectives  ←  train
#
# A header may include headers of its own folder and of the folders below it, never above it
# or beside it (nn, sim and optim know nothing of each other). sbptt.hpp, the umbrella, may
# include everything. Fails with one line per offending include.
#   cmake -DINCLUDE_DIR=<dir> -P layers.cmake
cmake_minimum_required(VERSION 3.20)
if(NOT INCLUDE_DIR)
  message(FATAL_ERROR "layers.cmake: pass -DINCLUDE_DIR=<the include directory>")
endif()

get_filename_component(INCLUDE_DIR "${INCLUDE_DIR}" ABSOLUTE)

# Each layer and the layers it may include (itself included).
set(_allowed_core core)
set(_allowed_nn core nn)
set(_allowed_sim core sim)
set(_allowed_optim core optim)
set(_allowed_bptt core nn sim optim bptt)
set(_allowed_objectives core nn sim optim bptt objectives)
set(_allowed_train core nn sim optim bptt objectives train)
set(_layers core nn sim optim bptt objectives train)

file(GLOB_RECURSE _headers RELATIVE ${INCLUDE_DIR}/sbptt ${INCLUDE_DIR}/sbptt/*.hpp)
set(_violations "")
set(_checked 0)
foreach(_header IN LISTS _headers)
  if(_header STREQUAL "sbptt.hpp")
    continue()
  endif()
  string(REGEX MATCH "^[^/]+" _layer "${_header}")
  if(NOT _layer IN_LIST _layers)
    string(APPEND _violations "  sbptt/${_header}: folder '${_layer}' is in no layer of the rule\n")
    continue()
  endif()
  math(EXPR _checked "${_checked} + 1")
  file(STRINGS ${INCLUDE_DIR}/sbptt/${_header} _includes REGEX "^[ \t]*#[ \t]*include[ \t]*[<\"]sbptt/")
  foreach(_line IN LISTS _includes)
    string(REGEX REPLACE "^[ \t]*#[ \t]*include[ \t]*[<\"]sbptt/([^\">]+)[\">].*$" "\\1" _target "${_line}")
    string(REGEX MATCH "^[^/]+" _target_layer "${_target}")
    if(_target STREQUAL "sbptt.hpp" OR NOT _target_layer IN_LIST _allowed_${_layer})
      string(APPEND _violations
             "  sbptt/${_header} (${_layer}) includes sbptt/${_target} (${_target_layer})\n")
    endif()
  endforeach()
endforeach()

if(_checked EQUAL 0)
  message(FATAL_ERROR "layers.cmake: no headers found under ${INCLUDE_DIR}/sbptt")
endif()
if(_violations)
  message(FATAL_ERROR "headers that include upward or sideways (docs/design.md, Layers):\n"
                      "${_violations}")
endif()
message(STATUS "layers: ${_checked} headers, every include goes down or stays in its folder")
