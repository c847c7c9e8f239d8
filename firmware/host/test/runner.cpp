#include "runner.h"

#include <vector>

namespace testing {
namespace {

struct Entry {
  const char* name;
  TestFunction function;
};

std::vector<Entry>& registry() {
  static std::vector<Entry> entries;
  return entries;
}

int g_failures = 0;

}  // namespace

void add(const char* name, TestFunction function) { registry().push_back({name, function}); }

void fail(const char* file, int line, const char* expression) {
  ++g_failures;
  std::printf("  %s:%d: CHECK(%s) failed\n", file, line, expression);
}

}  // namespace testing

int main() {
  int failed_tests = 0;
  for (const auto& entry : testing::registry()) {
    const int before = testing::g_failures;
    entry.function();
    const bool ok = testing::g_failures == before;
    failed_tests += ok ? 0 : 1;
    std::printf("%s %s\n", ok ? "ok  " : "FAIL", entry.name);
  }
  std::printf("%zu tests, %d failed\n", testing::registry().size(), failed_tests);
  return failed_tests;
}
