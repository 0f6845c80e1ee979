#pragma once
// Whether this test binary runs under AddressSanitizer (tools/check-sanitizers.sh). ASan owns
// the global allocation functions and reserves terabytes of address space for its shadow
// memory, so a test that replaces operator new or limits the address space (ulimit -v) checks
// something else under it and is skipped there.
#if defined(__SANITIZE_ADDRESS__)
#define SBPTT_TEST_ADDRESS_SANITIZER 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SBPTT_TEST_ADDRESS_SANITIZER 1
#endif
#endif
#ifndef SBPTT_TEST_ADDRESS_SANITIZER
#define SBPTT_TEST_ADDRESS_SANITIZER 0
#endif

namespace sbptt::testing {
inline constexpr bool address_sanitizer = SBPTT_TEST_ADDRESS_SANITIZER != 0;
}  // namespace sbptt::testing
