// Key table rows of the vda5050 section (docs/guide/vda5050.md).
#include "key_builders.hpp"

namespace agv::config::detail {

void add_vda5050_keys(std::vector<Key>* k) {
  k->push_back(boolean("vda5050.enabled", AGV_AT(vda5050.enabled), false,
                       "publish the pose to a VDA 5050 fleet broker. Off: no MQTT thread, no "
                       "socket; the CAN output is the same either way"));
  k->push_back(
      text("vda5050.broker_host", AGV_AT(vda5050.broker_host), "localhost",
           "MQTT broker (host name or address). Unreachable: the publisher retries "
           "with backoff (0.1 s, doubling up to 1 s between attempts) and the loop runs on"));
  k->push_back(integer("vda5050.broker_port", AGV_AT(vda5050.broker_port), 1, 65535, 1883,
                       {"", "broker TCP port; 8883 is the usual TLS port"}));
  k->push_back(text("vda5050.interface_name", AGV_AT(vda5050.interface_name), "uagv",
                    "first topic level (`interfaceName/v2/manufacturer/serialNumber/topic`); "
                    "the fleet control's choice, `uagv` in the specification's examples"));
  k->push_back(choice("vda5050.version", AGV_AT(vda5050.version), {"2.1.0", "3.0.0"}, "2.1.0",
                      "protocol version of every message and the topics' `v2` / `v3`; must be "
                      "the fleet control's (3.0.0 renames agvPosition to mobileRobotPosition and "
                      "initPosition to initializePosition)"));
  k->push_back(text("vda5050.manufacturer", AGV_AT(vda5050.manufacturer), "agvloc",
                    "the vehicle's manufacturer as the fleet control knows it (topic level and "
                    "header); instant actions for another manufacturer are refused"));
  k->push_back(text("vda5050.serial_number", AGV_AT(vda5050.serial_number), "agv-0001",
                    "the vehicle's serial number (topic level, header, MQTT client id); must be "
                    "unique on the broker: a second client with it disconnects the first"));
  k->push_back(text("vda5050.map_id", AGV_AT(vda5050.map_id), "default",
                    "`mapId` of every position: the landmark map's name in the fleet control. "
                    "initPosition for another mapId is refused (agvloc knows one map)"));
  k->push_back(number("vda5050.rate_hz", AGV_AT(vda5050.rate_hz), 0.1, 100.0, 10.0,
                      {"Hz",
                       "visualization messages a second (the newest output tick each time). "
                       "Higher shows motion smoother in the fleet view at more broker load; "
                       "10 Hz is 1 m/s in 100 mm steps"}));
  k->push_back(
      text("vda5050.username", AGV_AT(vda5050.username), "", "MQTT user name; empty = anonymous"));
  k->push_back(text("vda5050.password_file", AGV_AT(vda5050.password_file), "",
                    "file whose first line is the MQTT password (kept out of the configuration, "
                    "mode 0600); relative to the configuration file; empty = none"));
  k->push_back(text("vda5050.tls_ca_file", AGV_AT(vda5050.tls_ca_file), "",
                    "CA certificate (PEM) that signed the broker's: set = TLS with the broker's "
                    "certificate and host name verified; relative to the configuration file; "
                    "empty = plain TCP"));
}

}  // namespace agv::config::detail
