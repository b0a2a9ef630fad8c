// agvloc-desk config apply: the snippets `calibrate intrinsics` and `calibrate vehicle` write,
// merged into a vehicle configuration as one text edit of it (docs/guide/commissioning.md). Pure:
// texts in, text out; the command (cmd_config.cpp) reads and writes the files and runs the checker.
#pragma once

#include <string>
#include <vector>

namespace agv::desk::config_apply {

struct Text {
  std::string name;  // for messages: the file name
  std::string text;
};

struct Change {
  std::string key;     // dotted configuration key
  std::string before;  // the base's value as written; empty = the base did not set it
  std::string after;   // the snippet's value as written
  std::string from;    // "snippet.yaml:7"
};

struct Merged {
  std::string text;
  std::vector<Change> changes;  // every snippet key, in snippet order (before == after: unchanged)
  // False when the base's layout could not be edited in place (e.g. a section written as a flow
  // mapping in a way the edit does not handle) and the text was re-emitted by yaml-cpp, which
  // drops comments.
  bool comments_kept = true;
};

// Merges the snippets' keys into base. Refused, with one line per problem in *errors: a snippet
// that is not YAML, a key the configuration does not have (a removed key names its
// replacement), a key given twice in one snippet, and two snippets setting one key to different
// values (naming the key, both values and both files). Values are not range-checked here: the
// caller runs the configuration checker on the result.
bool merge(const Text& base, const std::vector<Text>& snippets, Merged* out,
           std::vector<std::string>* errors);

}  // namespace agv::desk::config_apply
