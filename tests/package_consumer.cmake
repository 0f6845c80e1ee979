# Installs sbptt into a scratch prefix, then configures, builds and runs examples/consumer
# and examples/consumer_mujoco (the opt-in MuJoCo component, on the cart pole of
# tests/models) against it; the plain consumer also with sbptt::native, and a strict one with
# -Wall -Wextra -Werror; and a copy of
# examples/train_own_scene.cpp with point_mass.hpp alone in a folder of its own, which the docs
# offer as the template to copy (it must need nothing else). Any failing step fails
# the test, and so does a plain consumer compiled for the same instruction set as the native one
# when that is wider than SSE2 (sbptt::sbptt must not force -march=native on consumers).
file(REMOVE_RECURSE ${WORK_DIR})
include(${CMAKE_CURRENT_LIST_DIR}/run_step.cmake)
run_step(${CMAKE_COMMAND} -S ${SOURCE_DIR} -B ${WORK_DIR}/library -G ${GENERATOR}
         -DSBPTT_BUILD_TESTS=OFF -DSBPTT_BUILD_EXAMPLES=OFF -DCMAKE_INSTALL_PREFIX=${WORK_DIR}/prefix)
run_step(${CMAKE_COMMAND} --install ${WORK_DIR}/library)
run_step(${CMAKE_COMMAND} -S ${SOURCE_DIR}/examples/consumer -B ${WORK_DIR}/consumer -G ${GENERATOR}
         -DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix -DCMAKE_BUILD_TYPE=Release)
run_step(${CMAKE_COMMAND} --build ${WORK_DIR}/consumer)
run_step(${WORK_DIR}/consumer/consumer)
string(REGEX MATCH "^[^ ]+" plain "${step_output}")
run_step(${WORK_DIR}/consumer/consumer_native)
string(REGEX MATCH "^[^ ]+" native "${step_output}")
run_step(${WORK_DIR}/consumer/consumer_strict)
if(plain STREQUAL native AND NOT native STREQUAL "SSE2")
  message(FATAL_ERROR "the plain consumer was compiled for ${plain}, as the native one: "
                      "sbptt::sbptt forces the build machine's instruction set on consumers")
endif()
run_step(${CMAKE_COMMAND} -S ${SOURCE_DIR}/examples/consumer_mujoco -B ${WORK_DIR}/consumer_mujoco
         -G ${GENERATOR} -DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix -DCMAKE_BUILD_TYPE=Release)
run_step(${CMAKE_COMMAND} --build ${WORK_DIR}/consumer_mujoco)
run_step(${WORK_DIR}/consumer_mujoco/consumer_mujoco ${SOURCE_DIR}/tests/models/cartpole_physical_2.xml)

set(own_scene ${WORK_DIR}/own_scene_copy)
file(COPY ${SOURCE_DIR}/examples/train_own_scene.cpp ${SOURCE_DIR}/examples/common/point_mass.hpp
     DESTINATION ${own_scene})
file(WRITE ${own_scene}/CMakeLists.txt "cmake_minimum_required(VERSION 3.20)
project(own_scene LANGUAGES CXX)
find_package(sbptt CONFIG REQUIRED)
add_executable(train_own_scene train_own_scene.cpp)
target_link_libraries(train_own_scene PRIVATE sbptt::sbptt)
")
run_step(${CMAKE_COMMAND} -S ${own_scene} -B ${own_scene}/build -G ${GENERATOR}
         -DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix -DCMAKE_BUILD_TYPE=Release)
run_step(${CMAKE_COMMAND} --build ${own_scene}/build)
run_step(${own_scene}/build/train_own_scene ${own_scene}/build)
if(NOT step_output MATCHES "best test loss")
  message(FATAL_ERROR "the copied train_own_scene did not train:\n${step_output}")
endif()
