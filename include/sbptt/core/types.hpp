#pragma once
/// \file Scalar, vector and matrix aliases used across sbptt.
///
/// Batches are stored one sample per column (column-major), so a batch of states of a
/// simulator with `state_dim()` d and batch size B is a d × B matrix.
#include <type_traits>

#include <Eigen/Core>

namespace sbptt {

using Index = Eigen::Index;

/// Dynamic column vector (flat parameter vectors, gradients).
template <class Scalar>
using Vector = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;

/// Dynamic column-major matrix (a batch: one sample per column).
template <class Scalar>
using Matrix = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;

/// Row-major dynamic matrix, the storage order of weights inside a flat parameter vector.
template <class Scalar>
using RowMajorMatrix = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

/// The IEEE scalars that the register kernels (AVX-512, AVX2) and the tests on bits are
/// written for.
template <class Scalar>
concept FloatOrDouble = std::is_same_v<Scalar, float> || std::is_same_v<Scalar, double>;

}  // namespace sbptt
