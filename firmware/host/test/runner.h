// A tiny test runner for the firmware's host tests (no framework to download).
//
//   TEST(name) { CHECK(condition); CHECK_NEAR(a, b, tolerance); }
//
// Every failed check prints its file, line and expression; the program's exit status is
// the number of failed tests (0: all passed).
#pragma once

#include <cmath>
#include <cstdio>

namespace testing {

using TestFunction = void (*)();
void add(const char* name, TestFunction function);
void fail(const char* file, int line, const char* expression);

struct Registrar {
  Registrar(const char* name, TestFunction function) { add(name, function); }
};

}  // namespace testing

#define TEST(name)                                              \
  static void test_##name();                                    \
  static testing::Registrar registrar_##name(#name, test_##name); \
  static void test_##name()

#define CHECK(condition) \
  ((condition) ? (void)0 : testing::fail(__FILE__, __LINE__, #condition))

#define CHECK_NEAR(a, b, tolerance) \
  ((std::fabs((a) - (b)) <= (tolerance)) ? (void)0 : testing::fail(__FILE__, __LINE__, #a " ~ " #b))
