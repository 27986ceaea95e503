#pragma once
// The message a test expects from code that refuses bad input (file, line, key and what to
// do): error_of<E>(f) runs f and returns what() of the E it throws, "" when it throws
// nothing. Any other exception escapes and fails the test with its own message.
#include <exception>
#include <string>
#include <utility>

namespace arnav::testing {

template <class E = std::exception, class F>
std::string error_of(F&& f) {
  try {
    std::forward<F>(f)();
  } catch (const E& e) {
    return e.what();
  }
  return "";
}

}  // namespace arnav::testing
