#pragma once
/// \file Exception types. The library never prints and never exits: every failure is one of
/// these, with a message that names the offending value and what was expected.
#include <locale>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

namespace sbptt {

/// Base of every sbptt exception.
class Error : public std::runtime_error {
public:
  using std::runtime_error::runtime_error;
};

/// A size, count, setting or number outside what the callee accepts.
class InvalidArgument : public Error {
public:
  using Error::Error;
};

/// Text that is not in the expected interchange format (docs/formats.md).
class ParseError : public Error {
public:
  using Error::Error;
};

/// A file or directory that cannot be read or written.
class IoError : public Error {
public:
  using Error::Error;
};

/// A resource the system would not give: a thread (a process or memory limit).
class ResourceError : public Error {
public:
  using Error::Error;
};

/// A NaN or Inf where a finite number is required.
class NonFiniteError : public Error {
public:
  using Error::Error;
};

namespace detail {

/// Streams every argument into one string: `concat("batch = ", b, ", expected > 0")`. In the
/// classic locale, whatever the global one: checkpoints are written with it, and a locale that
/// groups thousands would write "epoch 1.200".
template <class... Parts>
[[nodiscard]] std::string concat(Parts&&... parts) {
  std::ostringstream out;
  out.imbue(std::locale::classic());
  out.precision(17);
  (out << ... << std::forward<Parts>(parts));
  return out.str();
}

/// Throws `Exception` with the concatenated message unless `condition` holds.
template <class Exception = InvalidArgument, class... Parts>
void require(bool condition, Parts&&... parts) {
  if (!condition) throw Exception(concat(std::forward<Parts>(parts)...));
}

/// `work()`, with "`prefix`: " in front of the message of an `InvalidArgument`, `ParseError`,
/// `IoError`, `NonFiniteError` or `ResourceError` it throws, rethrown as that type: a reader
/// names its file, and only its caller knows which flag or setting gave it.
template <class Work>
decltype(auto) prefixing_errors(const std::string& prefix, Work&& work) {
  try {
    return work();
  } catch (const InvalidArgument& e) {
    throw InvalidArgument(concat(prefix, ": ", e.what()));
  } catch (const ParseError& e) {
    throw ParseError(concat(prefix, ": ", e.what()));
  } catch (const IoError& e) {
    throw IoError(concat(prefix, ": ", e.what()));
  } catch (const NonFiniteError& e) {
    throw NonFiniteError(concat(prefix, ": ", e.what()));
  } catch (const ResourceError& e) {
    throw ResourceError(concat(prefix, ": ", e.what()));
  }
}

}  // namespace detail
}  // namespace sbptt
