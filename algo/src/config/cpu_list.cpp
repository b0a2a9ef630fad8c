#include "agv/config/cpu_list.hpp"

#include <algorithm>
#include <cctype>

namespace agv::config {
namespace {

std::string trim(const std::string& s) {
  std::size_t b = 0, e = s.size();
  while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
  return s.substr(b, e - b);
}

// A decimal CPU number, at most kMaxCpu; no sign, no spaces inside.
bool parse_cpu(const std::string& s, int* cpu) {
  if (s.empty() || s.size() > 4) return false;
  int v = 0;
  for (const char ch : s) {
    if (ch < '0' || ch > '9') return false;
    v = v * 10 + (ch - '0');
  }
  if (v > kMaxCpu) return false;
  *cpu = v;
  return true;
}

}  // namespace

bool parse_cpu_list(const std::string& text, std::vector<int>* cpus, std::string* error) {
  cpus->clear();
  if (trim(text).empty()) return true;
  std::vector<bool> seen(kMaxCpu + 1, false);
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t comma = std::min(text.find(',', start), text.size());
    const std::string item = trim(text.substr(start, comma - start));
    const std::size_t dash = item.find('-');
    int lo = 0, hi = 0;
    const bool ok = dash == std::string::npos
                        ? parse_cpu(item, &lo) && parse_cpu(item, &hi)
                        : parse_cpu(trim(item.substr(0, dash)), &lo) &&
                              parse_cpu(trim(item.substr(dash + 1)), &hi) && lo <= hi;
    if (!ok) {
      *error = "\"" + item + "\" in \"" + text + "\" is not a CPU (0.." + std::to_string(kMaxCpu) +
               ") or a range N-M with N <= M";
      cpus->clear();
      return false;
    }
    for (int c = lo; c <= hi; ++c) seen[static_cast<std::size_t>(c)] = true;
    start = comma + 1;
  }
  for (int c = 0; c <= kMaxCpu; ++c)
    if (seen[static_cast<std::size_t>(c)]) cpus->push_back(c);
  return true;
}

}  // namespace agv::config
