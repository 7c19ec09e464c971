// A VDA 5050 master control written with vda-5050-lib (npm), driven by JSON lines on stdin:
//   {"cmd": "order", "order": {...headerless order...}}
//   {"cmd": "instantActions", "body": {...headerless instantActions...}}
//   {"cmd": "stop"}
// and printing JSON lines on stdout: {"event": "ready"}, {"event": "state", "state": {...}},
// {"event": "connection", "state": "ONLINE"}, {"event": "published", "topic": ...}, {"event": "error", ...}.
// argv: <module dir> <brokerUrl> <interfaceName> <manufacturer> <serialNumber> <vdaVersion>
const path = require("path");
const [moduleDir, brokerUrl, interfaceName, manufacturer, serialNumber, vdaVersion] = process.argv.slice(2);
const { MasterControlClient, Topic } = require(path.join(moduleDir, "node_modules", "vda-5050-lib"));
const readline = require("readline");

function emit(event) { process.stdout.write(JSON.stringify(event) + "\n"); }

(async () => {
    const agv = { manufacturer, serialNumber };
    const mc = new MasterControlClient({ interfaceName, transport: { brokerUrl }, vdaVersion });
    await mc.start();
    mc.trackAgvs((agvId, state) => emit({ event: "connection", agv: agvId, state }));
    await mc.subscribe(Topic.State, agv, state => emit({ event: "state", state }));
    emit({ event: "ready" });
    const rl = readline.createInterface({ input: process.stdin });
    for await (const line of rl) {
        let cmd;
        try { cmd = JSON.parse(line); } catch (e) { emit({ event: "error", error: String(e) }); continue; }
        try {
            if (cmd.cmd === "order") {
                await mc.publish(Topic.Order, agv, cmd.order);
                emit({ event: "published", topic: "order" });
            } else if (cmd.cmd === "instantActions") {
                await mc.publish(Topic.InstantActions, agv, cmd.body);
                emit({ event: "published", topic: "instantActions" });
            } else if (cmd.cmd === "stop") {
                break;
            }
        } catch (e) {
            emit({ event: "error", error: String(e && e.message || e) });
        }
    }
    await mc.stop();
    process.exit(0);
})().catch(e => { emit({ event: "fatal", error: String(e && e.stack || e) }); process.exit(1); });
