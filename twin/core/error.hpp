#pragma once
/// The project's exception hierarchy. Every message is one line that says
/// what is wrong, the value, and where (file, line, key, axis, time).
#include <stdexcept>
#include <string>

namespace twin {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
/// Bad input from a user: a file, a key, a value, a command-line option.
class ConfigError : public Error {
 public:
  using Error::Error;
};
/// A model that cannot go on: unstable gains, a non-finite state.
class ModelError : public Error {
 public:
  using Error::Error;
};
/// The ODE integrator failed.
class SolverError : public Error {
 public:
  using Error::Error;
};
/// Reading or writing files.
class IoError : public Error {
 public:
  using Error::Error;
};
/// A broken invariant inside the project (a bug, never bad input).
class InternalError : public Error {
 public:
  using Error::Error;
};

}  // namespace twin
