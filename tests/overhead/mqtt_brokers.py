"""MQTT brokers of their own for the script tests, on free loopback ports: mosquitto, and RabbitMQ
with its MQTT plugin (a second implementation, to show agvloc-overhead depends on MQTT 3.1.1, not
on mosquitto). start_broker(kind, work) -> (port, stop) or None when the broker is not installed."""
import os, shutil, signal, socket, subprocess, sys, time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "vda5050"))
from mqtt_replay import free_port  # noqa: E402


def wait_port(port, timeout_s):
    end = time.time() + timeout_s
    while time.time() < end:
        try:
            socket.create_connection(("127.0.0.1", port), 0.2).close()
            return True
        except OSError:
            time.sleep(0.1)
    return False


def _stopper(procs):
    def stop():
        for p in reversed(procs):
            try:
                os.killpg(p.pid, signal.SIGKILL)  # the broker's whole session (Erlang forks helpers)
            except ProcessLookupError:
                pass
            p.wait(10)
    return stop


def _popen(cmd, log, env=None):
    return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env,
                            start_new_session=True)


def _mosquitto(work):
    broker = shutil.which("mosquitto") or (
        "/usr/sbin/mosquitto" if os.path.exists("/usr/sbin/mosquitto") else None)
    if not broker:
        return None
    port = free_port()
    conf = os.path.join(work, "mosquitto.conf")
    with open(conf, "w") as f:
        f.write("listener %d 127.0.0.1\nallow_anonymous true\npersistence false\n" % port)
    procs = [_popen([broker, "-c", conf], subprocess.DEVNULL)]
    return port, procs, 5.0


def _rabbitmq(work):
    server = "/usr/lib/rabbitmq/bin/rabbitmq-server"  # not /usr/sbin's wrapper: no user switch
    epmd = shutil.which("epmd")
    if not os.path.exists(server) or not epmd:
        return None
    base = os.path.join(work, "rabbitmq")
    shutil.rmtree(base, ignore_errors=True)
    os.makedirs(base)
    port, amqp, dist, epmd_port = free_port(), free_port(), free_port(), free_port()
    with open(os.path.join(base, "rabbitmq.conf"), "w") as f:
        f.write("listeners.tcp.default = %d\nmqtt.listeners.tcp.default = %d\n"
                "mqtt.allow_anonymous = true\nloopback_users = none\n" % (amqp, port))
    with open(os.path.join(base, "enabled_plugins"), "w") as f:
        f.write("[rabbitmq_mqtt].\n")
    env = dict(os.environ, HOME=base, RABBITMQ_CONFIG_FILE=os.path.join(base, "rabbitmq.conf"),
               RABBITMQ_ENABLED_PLUGINS_FILE=os.path.join(base, "enabled_plugins"),
               RABBITMQ_MNESIA_BASE=os.path.join(base, "mnesia"),
               RABBITMQ_LOG_BASE=os.path.join(base, "log"), RABBITMQ_LOGS="-",
               RABBITMQ_PID_FILE=os.path.join(base, "pid"),
               RABBITMQ_NODENAME="agvtest%d@localhost" % port, RABBITMQ_DIST_PORT=str(dist),
               ERL_EPMD_PORT=str(epmd_port))
    log = open(os.path.join(base, "server.log"), "w")
    # An epmd of our own in the foreground: the one the server would start is a daemon that
    # outlives the test.
    procs = [_popen([epmd, "-port", str(epmd_port)], log, env)]
    procs.append(_popen([server], log, env))
    return port, procs, 90.0  # an Erlang node boots in 5-20 s on a loaded 2-core machine


def start_broker(kind, work):
    started = {"mosquitto": _mosquitto, "rabbitmq": _rabbitmq}[kind](work)
    if started is None:
        return None
    port, procs, boot_s = started
    stop = _stopper(procs)
    if not wait_port(port, boot_s):
        stop()
        raise RuntimeError("%s did not listen on port %d within %g s" % (kind, port, boot_s))
    return port, stop
