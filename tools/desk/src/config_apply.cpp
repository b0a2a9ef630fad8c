#include "config_apply.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <map>

#include "agv/config/keys.hpp"
#include "agv/config/yaml_keys.hpp"

namespace agv::desk::config_apply {

namespace {

std::vector<std::string> split(const std::string& key) {
  std::vector<std::string> parts;
  size_t start = 0;
  for (size_t dot; (dot = key.find('.', start)) != std::string::npos; start = dot + 1) {
    parts.push_back(key.substr(start, dot - start));
  }
  parts.push_back(key.substr(start));
  return parts;
}

// Numbers compare as numbers ("1.50" and "1.5" agree, "0x300" and "768" too); the rest as text.
bool same_value(const config::Key& k, const std::string& a, const std::string& b) {
  if (a == b) return true;
  if (k.type == config::KeyType::kString || k.type == config::KeyType::kChoice ||
      k.type == config::KeyType::kBool) {
    return false;
  }
  char *ea = nullptr, *eb = nullptr;
  const bool hex = k.type == config::KeyType::kCanId || k.type == config::KeyType::kInteger;
  const double va =
      hex ? static_cast<double>(std::strtoll(a.c_str(), &ea, 0)) : std::strtod(a.c_str(), &ea);
  const double vb =
      hex ? static_cast<double>(std::strtoll(b.c_str(), &eb, 0)) : std::strtod(b.c_str(), &eb);
  return *ea == '\0' && *eb == '\0' && va == vb;
}

// As it goes into the YAML: plain when that reads back as the same text, else double-quoted.
std::string yaml_scalar(const std::string& v) {
  const bool plain = !v.empty() && std::all_of(v.begin(), v.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-' || c == '+' ||
           c == '_' || c == '/';
  });
  if (plain) return v;
  std::string q = "\"";
  for (const char c : v) {
    if (c == '"' || c == '\\') q += '\\';
    q += c;
  }
  return q + "\"";
}

// End of the scalar that starts at pos (a quoted scalar with its closing quote; a plain one up to
// a comment, the end of the line or, in a flow mapping, the next separator).
size_t scalar_end(const std::string& t, size_t pos, bool flow) {
  if (pos >= t.size()) return std::string::npos;
  if (t[pos] == '"') {
    for (size_t j = pos + 1; j < t.size(); ++j) {
      if (t[j] == '\\') {
        ++j;
      } else if (t[j] == '"') {
        return j + 1;
      }
    }
    return std::string::npos;
  }
  if (t[pos] == '\'') {
    for (size_t j = pos + 1; j < t.size(); ++j) {
      if (t[j] != '\'') continue;
      if (j + 1 < t.size() && t[j + 1] == '\'') {
        ++j;
      } else {
        return j + 1;
      }
    }
    return std::string::npos;
  }
  size_t j = pos;
  while (j < t.size() && t[j] != '\n') {
    if (t[j] == '#' && j > pos && (t[j - 1] == ' ' || t[j - 1] == '\t')) break;
    if (flow && (t[j] == ',' || t[j] == '}' || t[j] == ']')) break;
    ++j;
  }
  while (j > pos && (t[j - 1] == ' ' || t[j - 1] == '\t' || t[j - 1] == '\r')) --j;
  return j;
}

// The key's block text: "sec:\n  leaf: v\n" at indentation `indent`.
std::string block_text(const std::vector<std::string>& parts, size_t from, size_t indent,
                       const std::string& value) {
  std::string s;
  for (size_t i = from; i < parts.size(); ++i) {
    s += std::string(indent + 2 * (i - from), ' ') + parts[i] + ":";
    s += i + 1 == parts.size() ? " " + yaml_scalar(value) + "\n" : "\n";
  }
  return s;
}

std::string flow_text(const std::vector<std::string>& parts, size_t from,
                      const std::string& value) {
  if (from + 1 == parts.size()) return parts[from] + ": " + yaml_scalar(value);
  return parts[from] + ": {" + flow_text(parts, from + 1, value) + "}";
}

// One key set in the text, keeping everything else as written. False when the layout is not
// one this edit handles (the caller then re-emits).
bool edit_in_place(std::string* text, const std::string& key, const std::string& value) {
  const std::vector<std::string> parts = split(key);
  YAML::Node root;
  try {
    root = YAML::Load(*text);
  } catch (const YAML::Exception&) {
    return false;
  }
  if (root.IsNull()) {
    *text += block_text(parts, 0, 0, value);
    return true;
  }
  if (!root.IsMap()) return false;
  const YAML::Node& croot = root;
  std::vector<YAML::Node> chain{croot};
  size_t depth = 0;
  for (; depth < parts.size(); ++depth) {
    const YAML::Node& parent = chain.back();
    const YAML::Node child = parent[parts[depth]];
    if (!child.IsDefined()) break;
    chain.push_back(child);
    if (!child.IsMap()) {
      ++depth;
      break;
    }
  }
  const YAML::Node& last = chain.back();
  if (depth == parts.size()) {  // the key exists: replace its scalar
    if (!last.IsScalar()) return false;
    const YAML::Node& owner = chain[chain.size() - 2];
    const size_t pos = static_cast<size_t>(last.Mark().pos);
    const size_t end = scalar_end(*text, pos, owner.Style() == YAML::EmitterStyle::Flow);
    if (end == std::string::npos || end < pos) return false;
    text->replace(pos, end - pos, yaml_scalar(value));
    return true;
  }
  if (!last.IsMap()) return false;  // a section written as a value (`mounting: 5`) or empty
  if (chain.size() == 1) {          // a new top-level section: at the end
    if (last.Style() == YAML::EmitterStyle::Flow) return false;
    if (!text->empty() && text->back() != '\n') *text += '\n';
    *text += block_text(parts, depth, 0, value);
    return true;
  }
  if (last.Style() == YAML::EmitterStyle::Flow) {
    const size_t brace = static_cast<size_t>(last.Mark().pos);
    if (brace >= text->size() || (*text)[brace] != '{') return false;
    const bool empty = last.size() == 0;
    text->insert(brace + 1, flow_text(parts, depth, value) + (empty ? "" : ", "));
    return true;
  }
  // A block section: the new key goes before its first key, at that key's indentation.
  if (last.size() == 0) return false;
  YAML::Mark m;
  for (const auto& kv : last) {
    const YAML::Node first_key = kv.first;
    m = first_key.Mark();
    break;
  }
  const size_t line_start = static_cast<size_t>(m.pos) - static_cast<size_t>(m.column);
  if (text->find_first_not_of(' ', line_start) != static_cast<size_t>(m.pos)) return false;
  text->insert(line_start, block_text(parts, depth, static_cast<size_t>(m.column), value));
  return true;
}

// yaml-cpp's emitter: always possible, but comments are lost.
bool re_emit(std::string* text, const std::vector<Change>& changes) {
  try {
    YAML::Node root = YAML::Load(*text);
    if (root.IsNull()) root = YAML::Node(YAML::NodeType::Map);
    for (const Change& c : changes) {
      const std::vector<std::string> parts = split(c.key);
      std::vector<YAML::Node> chain{root};
      for (size_t i = 0; i + 1 < parts.size(); ++i) {
        YAML::Node n = chain.back()[parts[i]];
        if (!n.IsMap()) n = YAML::Node(YAML::NodeType::Map);
        chain.back()[parts[i]] = n;
        chain.push_back(n);
      }
      chain.back()[parts.back()] = c.after;
    }
    YAML::Emitter e;
    e << root;
    if (!e.good()) return false;
    *text = std::string(e.c_str()) + "\n";
    return true;
  } catch (const YAML::Exception&) {
    return false;
  }
}

// The text gives exactly the base's keys with the changes applied: what the edit must achieve,
// checked on the result rather than trusted.
bool holds(const std::string& text, const std::vector<config::YamlEntry>& base,
           const std::vector<Change>& changes) {
  std::vector<config::YamlEntry> got;
  std::string err;
  if (!config::yaml_entries(text, &got, &err)) return false;
  std::map<std::string, std::string> want, have;
  for (const auto& e : base) want[e.key] = e.value;
  for (const auto& c : changes) want[c.key] = c.after;
  for (const auto& e : got) {
    if (!have.emplace(e.key, e.value).second) return false;  // a key now twice
  }
  return have == want;
}

}  // namespace

bool merge(const Text& base, const std::vector<Text>& snippets, Merged* out,
           std::vector<std::string>* errors) {
  const size_t errors_before = errors->size();
  std::vector<config::YamlEntry> base_entries;
  std::string err;
  if (!config::yaml_entries(base.text, &base_entries, &err)) {
    errors->push_back(base.name + ": " + err);
    return false;
  }
  std::map<std::string, std::string> base_value;
  std::map<std::string, int> base_line;
  for (const auto& e : base_entries) {
    base_value.emplace(e.key, e.value);
    if (const auto [it, fresh] = base_line.emplace(e.key, e.line); !fresh) {
      errors->push_back(base.name + ":" + std::to_string(e.line) + ": " + e.key +
                        ": given twice (first at line " + std::to_string(it->second) + ")");
    }
  }

  std::vector<Change> changes;
  std::map<std::string, size_t> by_key;  // index into changes
  for (const Text& s : snippets) {
    std::vector<config::YamlEntry> entries;
    if (!config::yaml_entries(s.text, &entries, &err)) {
      errors->push_back(s.name + ": " + err);
      continue;
    }
    if (entries.empty()) {
      errors->push_back(s.name + ": no configuration key (a calibration that determined nothing?)");
      continue;
    }
    std::map<std::string, int> seen_here;
    for (const auto& e : entries) {
      const std::string where = s.name + ":" + std::to_string(e.line);
      const config::Key* k = config::find_key(e.key);
      if (!k) {
        std::string hint = "not a configuration key (docs/guide/config.md)";
        for (const auto& r : config::removed_keys()) {
          if (r.name == e.key) hint = "removed; " + r.replacement;
        }
        errors->push_back(where + ": " + e.key + ": " + hint);
        continue;
      }
      if (const auto [it, fresh] = seen_here.emplace(e.key, e.line); !fresh) {
        errors->push_back(where + ": " + e.key + ": given twice (first at line " +
                          std::to_string(it->second) + ")");
        continue;
      }
      const auto b = base_value.find(e.key);
      Change c{e.key, b == base_value.end() ? std::string() : b->second, e.value, where};
      const auto prev = by_key.find(e.key);
      if (prev == by_key.end()) {
        by_key.emplace(e.key, changes.size());
        changes.push_back(c);
      } else if (!same_value(*k, changes[prev->second].after, e.value)) {
        errors->push_back(e.key + ": " + changes[prev->second].from + " sets " +
                          changes[prev->second].after + ", " + where + " sets " + e.value +
                          ": apply one of them");
      }
    }
  }
  if (errors->size() != errors_before) return false;

  Merged m;
  m.text = base.text;
  bool in_place = true;
  for (const Change& c : changes) {
    if (!edit_in_place(&m.text, c.key, c.after)) {
      in_place = false;
      break;
    }
  }
  if (!in_place || !holds(m.text, base_entries, changes)) {
    m.text = base.text;
    m.comments_kept = false;
    if (!re_emit(&m.text, changes) || !holds(m.text, base_entries, changes)) {
      errors->push_back(base.name + ": cannot set the snippets' keys in this file's layout");
      return false;
    }
  }
  m.changes = std::move(changes);
  *out = std::move(m);
  return true;
}

}  // namespace agv::desk::config_apply
