// The network kernels' float and double instances, compiled once for a whole build with
// SBPTT_SEPARATE_KERNELS (CMake option of the same name; docs/testing.md), where every other
// translation unit sees the explicit instantiation declarations at the end of the headers.
#include "sbptt/nn/outer_product.hpp"
#include "sbptt/nn/packed_product.hpp"

namespace sbptt {
template void PackedMatrix<float>::multiply(const float*, Index, Index, float*, Index,
                                            const float*) const;
template void PackedMatrix<double>::multiply(const double*, Index, Index, double*, Index,
                                             const double*) const;
template void add_outer_products(float*, Index, Index, const float*, const float*, Index,
                                 const float*);
template void add_outer_products(double*, Index, Index, const double*, const double*, Index,
                                 const double*);
namespace detail {
template void add_sample_sums(float*, Index, const float*, Index, const float*);
template void add_sample_sums(double*, Index, const double*, Index, const double*);
}  // namespace detail
}  // namespace sbptt
