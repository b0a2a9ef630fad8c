// VDA 5050 order encoder and strict decoder (order.hpp). Nothing throws: the text is bounded in
// size and nesting before the JSON parser sees it, and every refusal names the field.
#include "agv/vda5050/order.hpp"

#include <cmath>
#include <nlohmann/json.hpp>

#include "json_nesting.hpp"

namespace agv::vda5050 {

using nlohmann::json;

namespace {

constexpr int kOrderMaxDepth = 8;

bool order_depth_ok(std::string_view text) { return detail::nesting_within(text, kOrderMaxDepth); }

struct OrderReader {
  std::string* error;
  bool fail(const std::string& field, const char* why) {
    *error = field + ": " + why;
    return false;
  }
  bool str(const json& o, const char* key, const std::string& where, std::string* out) {
    const auto it = o.find(key);
    const std::string f = where + key;
    if (it == o.end()) return fail(f, "missing");
    if (!it->is_string()) return fail(f, "not a string");
    const auto& s = it->get_ref<const std::string&>();
    if (s.size() > kOrderMaxString) return fail(f, "longer than 256 characters");
    *out = s;
    return true;
  }
  bool uint(const json& o, const char* key, const std::string& where, std::uint32_t* out) {
    const auto it = o.find(key);
    const std::string f = where + key;
    if (it == o.end()) return fail(f, "missing");
    if (!it->is_number_integer() || (it->is_number_integer() && it->get<std::int64_t>() < 0) ||
        it->get<std::int64_t>() > 0xFFFFFFFFLL) {
      return fail(f, "not an integer in [0, 2^32)");
    }
    *out = static_cast<std::uint32_t>(it->get<std::int64_t>());
    return true;
  }
  bool boolean(const json& o, const char* key, const std::string& where, bool* out) {
    const auto it = o.find(key);
    if (it == o.end()) return fail(where + key, "missing");
    if (!it->is_boolean()) return fail(where + key, "not a boolean");
    *out = it->get<bool>();
    return true;
  }
  bool number(const json& o, const char* key, const std::string& where, double* out) {
    const auto it = o.find(key);
    if (it == o.end()) return fail(where + key, "missing");
    if (!it->is_number()) return fail(where + key, "not a number");
    *out = it->get<double>();
    if (!std::isfinite(*out)) return fail(where + key, "not finite");
    return true;
  }
  bool empty_actions(const json& o, const std::string& where) {
    const auto it = o.find("actions");
    if (it == o.end()) return fail(where + "actions", "missing");
    if (!it->is_array()) return fail(where + "actions", "not an array");
    if (!it->empty()) return fail(where + "actions", "actions are not supported (must be empty)");
    return true;
  }
  bool node(const json& j, const std::string& w, OrderNode* n) {
    if (!j.is_object()) return fail(w, "not an object");
    if (!str(j, "nodeId", w, &n->node_id) || !uint(j, "sequenceId", w, &n->sequence_id) ||
        !boolean(j, "released", w, &n->released) || !empty_actions(j, w)) {
      return false;
    }
    const auto p = j.find("nodePosition");
    if (p == j.end()) return true;
    const std::string pw = w + "nodePosition.";
    if (!p->is_object()) return fail(w + "nodePosition", "not an object");
    if (!number(*p, "x", pw, &n->x_m) || !number(*p, "y", pw, &n->y_m) ||
        !str(*p, "mapId", pw, &n->map_id)) {
      return false;
    }
    n->has_position = true;
    if (p->contains("theta")) {
      if (!number(*p, "theta", pw, &n->theta_rad)) return false;
      if (std::abs(n->theta_rad) > 3.14159265359) return fail(pw + "theta", "outside [-pi, pi]");
      n->has_theta = true;
    }
    return true;
  }
  bool edge(const json& j, const std::string& w, OrderEdge* e) {
    if (!j.is_object()) return fail(w, "not an object");
    return str(j, "edgeId", w, &e->edge_id) && uint(j, "sequenceId", w, &e->sequence_id) &&
           boolean(j, "released", w, &e->released) && str(j, "startNodeId", w, &e->start_node_id) &&
           str(j, "endNodeId", w, &e->end_node_id) && empty_actions(j, w);
  }
};

// Nodes even, edges odd, alternating from the first node; each edge joins its neighbours.
bool order_sequence_ok(const Order& o, std::string* error) {
  if (o.nodes.empty()) {
    *error = "nodes: empty";
    return false;
  }
  if (o.edges.size() + 1 != o.nodes.size()) {
    *error = "edges: " + std::to_string(o.edges.size()) + " edges for " +
             std::to_string(o.nodes.size()) + " nodes (need one fewer)";
    return false;
  }
  const std::uint32_t base = o.nodes[0].sequence_id;
  for (std::size_t i = 0; i < o.nodes.size(); ++i) {
    if (o.nodes[i].sequence_id != base + 2 * i || o.nodes[i].sequence_id % 2 != 0) {
      *error =
          "nodes[" + std::to_string(i) + "].sequenceId: expected " + std::to_string(base + 2 * i);
      return false;
    }
  }
  for (std::size_t i = 0; i < o.edges.size(); ++i) {
    const std::string w = "edges[" + std::to_string(i) + "].";
    if (o.edges[i].sequence_id != base + 2 * i + 1) {
      *error = w + "sequenceId: expected " + std::to_string(base + 2 * i + 1);
      return false;
    }
    if (o.edges[i].start_node_id != o.nodes[i].node_id) {
      *error = w + "startNodeId: expected " + o.nodes[i].node_id;
      return false;
    }
    if (o.edges[i].end_node_id != o.nodes[i + 1].node_id) {
      *error = w + "endNodeId: expected " + o.nodes[i + 1].node_id;
      return false;
    }
  }
  return true;
}

}  // namespace

Order order_from_waypoints(const std::vector<Vec2>& w, const std::string& map_id,
                           const Order& header) {
  Order o = header;
  o.nodes.clear();
  o.edges.clear();
  for (std::size_t i = 0; i < w.size(); ++i) {
    OrderNode n;
    n.node_id = o.order_id + "_n" + std::to_string(i);
    n.sequence_id = static_cast<std::uint32_t>(2 * i);
    n.has_position = true, n.x_m = w[i].x * 1e-3, n.y_m = w[i].y * 1e-3, n.map_id = map_id;
    const std::size_t a = i + 1 < w.size() ? i : (i > 0 ? i - 1 : i), b = a + 1;
    if (b < w.size()) {
      n.has_theta = true;
      n.theta_rad = wrap_angle_rad(std::atan2(w[b].y - w[a].y, w[b].x - w[a].x));
    }
    o.nodes.push_back(n);
    if (i + 1 < w.size()) {
      OrderEdge e;
      e.edge_id = o.order_id + "_e" + std::to_string(i);
      e.sequence_id = static_cast<std::uint32_t>(2 * i + 1);
      e.start_node_id = n.node_id;
      e.end_node_id = o.order_id + "_n" + std::to_string(i + 1);
      o.edges.push_back(e);
    }
  }
  return o;
}

std::string encode_order(const Order& o) {
  json j = {{"headerId", o.header_id},
            {"timestamp", o.timestamp},
            {"version", o.version},
            {"manufacturer", o.manufacturer},
            {"serialNumber", o.serial_number},
            {"orderId", o.order_id},
            {"orderUpdateId", o.order_update_id}};
  json nodes = json::array(), edges = json::array();
  for (const OrderNode& n : o.nodes) {
    json jn = {{"nodeId", n.node_id},
               {"sequenceId", n.sequence_id},
               {"released", n.released},
               {"actions", json::array()}};
    if (n.has_position) {
      jn["nodePosition"] = {{"x", n.x_m}, {"y", n.y_m}, {"mapId", n.map_id}};
      if (n.has_theta) jn["nodePosition"]["theta"] = n.theta_rad;
    }
    nodes.push_back(jn);
  }
  for (const OrderEdge& e : o.edges) {
    edges.push_back({{"edgeId", e.edge_id},
                     {"sequenceId", e.sequence_id},
                     {"released", e.released},
                     {"startNodeId", e.start_node_id},
                     {"endNodeId", e.end_node_id},
                     {"actions", json::array()}});
  }
  j["nodes"] = nodes;
  j["edges"] = edges;
  return j.dump(2);
}

bool parse_order(std::string_view text, Order* out, std::string* error) {
  if (text.size() > kOrderMaxBytes) {
    *error = "order: larger than 1 MiB";
    return false;
  }
  if (!order_depth_ok(text)) {
    *error = "order: nested deeper than 8";
    return false;
  }
  const json j = json::parse(text.begin(), text.end(), nullptr, false);
  if (j.is_discarded()) {
    *error = "order: not JSON";
    return false;
  }
  if (!j.is_object()) {
    *error = "order: not an object";
    return false;
  }
  OrderReader r{error};
  Order o;
  if (!r.uint(j, "headerId", "", &o.header_id) || !r.str(j, "timestamp", "", &o.timestamp) ||
      !r.str(j, "version", "", &o.version) || !r.str(j, "manufacturer", "", &o.manufacturer) ||
      !r.str(j, "serialNumber", "", &o.serial_number) || !r.str(j, "orderId", "", &o.order_id) ||
      !r.uint(j, "orderUpdateId", "", &o.order_update_id)) {
    return false;
  }
  for (const char* key : {"nodes", "edges"}) {
    const auto it = j.find(key);
    if (it == j.end()) return r.fail(key, "missing");
    if (!it->is_array()) return r.fail(key, "not an array");
    if (it->size() > kOrderMaxNodes) return r.fail(key, "more than 1000 entries");
  }
  for (std::size_t i = 0; i < j["nodes"].size(); ++i) {
    o.nodes.emplace_back();
    if (!r.node(j["nodes"][i], "nodes[" + std::to_string(i) + "].", &o.nodes.back())) return false;
  }
  for (std::size_t i = 0; i < j["edges"].size(); ++i) {
    o.edges.emplace_back();
    if (!r.edge(j["edges"][i], "edges[" + std::to_string(i) + "].", &o.edges.back())) return false;
  }
  if (!order_sequence_ok(o, error)) return false;
  *out = std::move(o);
  return true;
}

bool order_waypoints_mm(const Order& order, std::vector<Vec2>* out, std::string* error) {
  out->clear();
  for (std::size_t i = 0; i < order.nodes.size(); ++i) {
    const OrderNode& n = order.nodes[i];
    if (!n.has_position) {
      *error = "nodes[" + std::to_string(i) + "] (" + n.node_id + "): no nodePosition";
      return false;
    }
    out->push_back({n.x_m * 1e3, n.y_m * 1e3});
  }
  return true;
}

}  // namespace agv::vda5050
