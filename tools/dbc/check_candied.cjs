#!/usr/bin/env node
// Independent decoder check: decodes a candump -l log written by agv_can_tool with the candied
// DBC library (not our code) and compares every signal with the physical value the codec was
// given. Also recomputes the E2E CRC from the rule stated in the DBC/docs (CRC-8 SAE J1850 over
// E2EDataID low byte, high byte, then bytes 1..7) and checks the alive counter range.
//   node check_candied.cjs DBC LOG EXPECTED
'use strict';
const fs = require('fs');
const { Dbc, Can } = require('candied');

function crc8SaeJ1850(bytes) {
  let crc = 0xff;
  for (const b of bytes) {
    crc ^= b;
    for (let i = 0; i < 8; i++) crc = crc & 0x80 ? ((crc << 1) ^ 0x1d) & 0xff : (crc << 1) & 0xff;
  }
  return crc ^ 0xff;
}

function parseCandumpLine(line) {
  const m = /^\((\d+)\.(\d{6})\) (\S+) ([0-9A-F]{3}|[0-9A-F]{8})#([0-9A-F]*)$/.exec(line);
  if (!m) throw new Error(`not a candump -l line: ${line}`);
  const payload = [];
  for (let i = 0; i < m[5].length; i += 2) payload.push(parseInt(m[5].substr(i, 2), 16));
  return { id: parseInt(m[4], 16), extended: m[4].length === 8, payload };
}

function main() {
  const [dbcPath, logPath, expectedPath] = process.argv.slice(2);
  if (!expectedPath) {
    console.error('usage: check_candied.cjs DBC LOG EXPECTED');
    process.exit(2);
  }
  // Sanity of the CRC implementation itself (AUTOSAR check value).
  if (crc8SaeJ1850([0x00, 0x00, 0x00, 0x00]) !== 0x59) throw new Error('CRC self-test failed');

  const data = new Dbc().load(fs.readFileSync(dbcPath, 'utf8'));
  const can = new Can();
  can.database = data;
  const byId = new Map();
  for (const msg of data.messages.values()) byId.set(msg.id, msg);

  const lines = fs.readFileSync(logPath, 'utf8').split('\n').filter((l) => l.length > 0);
  const expected = fs.readFileSync(expectedPath, 'utf8').split('\n').filter((l) => l.length > 0)
      .map((l) => JSON.parse(l));
  if (lines.length !== expected.length || lines.length === 0) {
    console.error(`FAIL: ${lines.length} log lines vs ${expected.length} expectations`);
    process.exit(1);
  }
  let failures = 0, checked = 0;
  const fail = (i, msg) => {
    if (failures++ < 30) console.error(`FAIL line ${i + 1}: ${msg}`);
  };
  lines.forEach((line, i) => {
    const f = parseCandumpLine(line);
    const exp = expected[i];
    if (f.id !== exp.id || f.extended !== exp.extended) return fail(i, 'ID differs from expectation');
    const bound = can.decode(can.createFrame(f.id, f.payload, f.extended));
    if (!bound) return fail(i, `candied does not know ID 0x${f.id.toString(16)}`);
    const sigs = bound.boundSignals;
    for (const [name, [value, tol]] of Object.entries(exp.signals)) {
      const s = sigs.get(name);
      if (!s) { fail(i, `${bound.name}.${name} missing in DBC`); continue; }
      const got = typeof s.value === 'number' ? s.value : Number(s.rawValue);
      if (!(Math.abs(got - value) <= tol)) {
        fail(i, `${bound.name}.${name} = ${got}, expected ${value} +- ${tol}`);
      }
      checked++;
    }
    // E2E: CRC and counter from the documented rule.
    const msg = byId.get(f.id);
    const attr = msg.attributes && msg.attributes.get('E2EDataID');
    if (!attr) return fail(i, `${bound.name} has no E2EDataID attribute`);
    const dataId = Number(attr.value);
    const crc = crc8SaeJ1850([dataId & 0xff, dataId >> 8, ...f.payload.slice(1, 8)]);
    if (sigs.get('CRC').rawValue !== crc) {
      fail(i, `${bound.name}.CRC = ${sigs.get('CRC').rawValue}, recomputed ${crc}`);
    }
    const counter = sigs.get('AliveCounter').rawValue;
    if (!(counter >= 0 && counter <= 14)) fail(i, `${bound.name}.AliveCounter = ${counter}`);
    checked += 2;
  });
  if (failures > 0) {
    console.error(`FAIL: ${failures} mismatches in ${lines.length} frames`);
    process.exit(1);
  }
  console.log(`PASS: candied decoded ${lines.length} frames, ${checked} values agree`);
}

main();
