// Renders the contract from the signal table: the DBC file (can/agvloc.dbc is
// render_dbc(ProtocolConfig{}); integrators with another base ID render their own) and the
// Markdown frame table of docs/guide/can.md. Pure string generation.
#pragma once

#include <string>

#include "agv/protocol/codec.hpp"

namespace agv::protocol {

std::string render_dbc(const ProtocolConfig& cfg);
std::string render_markdown_table(const ProtocolConfig& cfg);

// Shortest decimal text that reads back as the same double (e.g. 0.1 -> "0.1").
std::string format_number(double v);

}  // namespace agv::protocol
