// agvloc-desk config apply (config_apply.hpp, merge): a configuration and calibration snippets,
// all user files. The input is the base text, then up to three snippets, each after a line
// "---snippet---". Property: a merge that succeeds gives a text whose keys are exactly the base's
// with each change's value (checked independently of merge's own check), every change naming a
// key and where it came from; a refused merge says why.
#include <map>

#include "agv/config/yaml_keys.hpp"
#include "config_apply.hpp"
#include "fuzz_check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  using agv::desk::config_apply::Text;
  const std::string in(agv::fuzz::as_text(data, size));
  static const std::string kSep = "\n---snippet---\n";
  std::vector<std::string> parts;
  std::size_t a = 0;
  for (;;) {
    const std::size_t b = in.find(kSep, a);
    if (b == std::string::npos || parts.size() == 3) {
      parts.push_back(in.substr(a));
      break;
    }
    parts.push_back(in.substr(a, b - a));
    a = b + kSep.size();
  }
  const Text base{"base.yaml", parts[0]};
  std::vector<Text> snippets;
  for (std::size_t i = 1; i < parts.size(); ++i) {
    snippets.push_back({"s" + std::to_string(i) + ".yaml", parts[i]});
  }
  agv::desk::config_apply::Merged m;
  std::vector<std::string> errors;
  if (!agv::desk::config_apply::merge(base, snippets, &m, &errors)) {
    FUZZ_CHECK(!errors.empty(), "a refused merge says why");
    return 0;
  }
  FUZZ_CHECK(errors.empty(), "a merge that succeeded reported %zu errors", errors.size());
  std::vector<agv::config::YamlEntry> want_base, got;
  std::string err;
  FUZZ_CHECK(agv::config::yaml_entries(base.text, &want_base, &err), "base accepted: %s",
             err.c_str());
  FUZZ_CHECK(agv::config::yaml_entries(m.text, &got, &err), "merged text is YAML: %s", err.c_str());
  std::map<std::string, std::string> want, have;
  for (const auto& e : want_base) want[e.key] = e.value;
  for (const auto& c : m.changes) {
    FUZZ_CHECK(!c.key.empty() && !c.from.empty(), "a change without key or origin");
    want[c.key] = c.after;
  }
  for (const auto& e : got) {
    FUZZ_CHECK(have.emplace(e.key, e.value).second, "key %s twice in the result", e.key.c_str());
  }
  FUZZ_CHECK(have == want, "the result's keys are the base's with the changes");
  return 0;
}
