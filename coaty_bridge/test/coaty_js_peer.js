// A Coaty JS agent (@coaty/core 2.4.1) for the interop test of coaty_bridge.
// Usage: node coaty_js_peer.js <brokerUrl> <namespace> <objectType> [<footprintObjectType>]
// Reads one JSON command per line on stdin, writes one JSON event per line on stdout:
//   {"cmd": "discoverIdentities"}       -> {"event": "identity", "object": ...} per Resolve
//   {"cmd": "publish", "object": {...}} -> Advertise; the object also answers obstacle Discovers
//   {"cmd": "publishFootprint", "object": {...}} -> Advertise of a robot footprint (not a Discover answer)
//   {"cmd": "publishRenewals", "object": {...}} -> Channel event on org.fleetsharing.ObstacleRenewals
//   {"cmd": "exit"}
// Events: ready, advertise (objects of <objectType>, with compact index strings decoded),
// deadvertise, discoverAnswered, footprint (objects of <footprintObjectType>), renewals (the objects of
// Channel events on org.fleetsharing.ObstacleRenewals, with the sender's sourceId), error.
"use strict";
const readline = require("readline");
const zlib = require("zlib");
const { Container, MqttBinding, AdvertiseEvent, ChannelEvent, DiscoverEvent, ResolveEvent } = require("@coaty/core");

const [brokerUrl, namespace, objectType, footprintType] = process.argv.slice(2);
const emit = (event) => process.stdout.write(JSON.stringify(event) + "\n");
const mine = [];
const RENEWALS_CHANNEL = "org.fleetsharing.ObstacleRenewals";

// The bridge's compact index form: base64 of LEB128 varints, first value then gaps;
// with a "z:" prefix the varint bytes are raw-deflated.
function decodeIndexes(value) {
    if (Array.isArray(value)) {
        return value;
    }
    const bytes = value.startsWith("z:") ? zlib.inflateRawSync(Buffer.from(value.slice(2), "base64"))
        : Buffer.from(value, "base64");
    const out = [];
    let current = 0, delta = 0, shift = 0;
    for (const byte of bytes) {
        delta += (byte & 0x7f) * Math.pow(2, shift);
        shift += 7;
        if (byte & 0x80) {
            continue;
        }
        current = out.length === 0 ? delta : current + delta;
        out.push(current);
        delta = 0;
        shift = 0;
    }
    return out;
}

const container = Container.resolve({}, {
    common: { agentIdentity: { name: "coaty-js-peer" } },
    communication: {
        binding: MqttBinding.withOptions({ brokerUrl, namespace }),
        shouldAutoStart: true,
    },
});
const com = container.communicationManager;

// first: a test that has seen an Advertise knows this subscription is in place too
com.observeChannel(RENEWALS_CHANNEL).subscribe(
    event => emit({ event: "renewals", object: event.data.object, sourceId: event.sourceId }));
com.observeAdvertiseWithObjectType(objectType).subscribe(event => {
    const object = event.data.object;
    emit({
        event: "advertise", object,
        marked: decodeIndexes(object.markedIndexes), cleared: decodeIndexes(object.clearedIndexes),
    });
});
if (footprintType) {
    com.observeAdvertiseWithObjectType(footprintType).subscribe(
        event => emit({ event: "footprint", object: event.data.object }));
}
com.observeDeadvertise().subscribe(event => emit({ event: "deadvertise", objectIds: event.data.objectIds }));
com.observeDiscover().subscribe(event => {
    if (event.data.isObjectTypeCompatible(objectType)) {
        for (const object of mine) {
            event.resolve(ResolveEvent.withObject(object));
        }
        emit({ event: "discoverAnswered", count: mine.length });
    }
});

const lines = readline.createInterface({ input: process.stdin });
lines.on("line", line => {
    let cmd;
    try {
        cmd = JSON.parse(line);
        if (cmd.cmd === "discoverIdentities") {
            com.publishDiscover(DiscoverEvent.withCoreTypes(["Identity"])).subscribe(
                resolve => emit({ event: "identity", object: resolve.data.object }),
                error => emit({ event: "error", message: String(error) }));
        } else if (cmd.cmd === "publish") {
            mine.push(cmd.object);
            com.publishAdvertise(AdvertiseEvent.withObject(cmd.object));
            emit({ event: "published", objectId: cmd.object.objectId });
        } else if (cmd.cmd === "publishFootprint") {
            com.publishAdvertise(AdvertiseEvent.withObject(cmd.object));
            emit({ event: "published", objectId: cmd.object.objectId });
        } else if (cmd.cmd === "publishRenewals") {
            com.publishChannel(ChannelEvent.withObject(RENEWALS_CHANNEL, cmd.object));
            emit({ event: "published", objectId: cmd.object.objectId });
        } else if (cmd.cmd === "exit") {
            container.shutdown();
            setTimeout(() => process.exit(0), 200);
        }
    } catch (error) {
        emit({ event: "error", message: String(error), line });
    }
});
lines.on("close", () => { container.shutdown(); setTimeout(() => process.exit(0), 200); });

com.observeCommunicationState().subscribe(state => {
    if (state === 1) {  // CommunicationState.Online
        emit({ event: "ready", identity: container.identity.objectId });
    }
});
