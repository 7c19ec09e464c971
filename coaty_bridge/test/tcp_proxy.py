"""A TCP proxy a test controls (not a test file): robots connect to the broker through it, and
cut() severs every connection and refuses new ones until heal() - a network partition of the
robots behind it, while the broker and everyone else keep running."""
import socket
import threading


class TcpProxy:
    def __init__(self, upstream_port, host="127.0.0.1"):
        self.upstream = (host, upstream_port)
        self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._server.bind((host, 0))
        self._server.listen(16)
        self.port = self._server.getsockname()[1]
        self.url = "mqtt://%s:%d" % (host, self.port)
        self._lock = threading.Lock()
        self._open = []        # sockets of live connections (both sides)
        self._cut = False
        self._closed = False
        # stall(): set = data flows; cleared = the pumps of that direction stop reading (the
        # connections stay open, the bytes wait in the kernel): a silent stall, not a partition
        self._flowing = {"up": threading.Event(), "down": threading.Event()}
        for event in self._flowing.values():
            event.set()
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        while not self._closed:
            try:
                client, _ = self._server.accept()
            except OSError:
                return
            with self._lock:
                refused = self._cut
            if refused:
                client.close()
                continue
            try:
                upstream = socket.create_connection(self.upstream, timeout=5)
            except OSError:
                client.close()
                continue
            for sock in (client, upstream):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._open += [client, upstream]
            threading.Thread(target=self._pump, args=(client, upstream, "up"), daemon=True).start()
            threading.Thread(target=self._pump, args=(upstream, client, "down"), daemon=True).start()

    def _pump(self, src, dst, direction):
        flowing = self._flowing[direction]
        try:
            while True:
                while not flowing.wait(0.05):
                    if self._closed:
                        return
                data = src.recv(65536)
                if not data:
                    break
                while not flowing.wait(0.05):   # read while a stall began: held back as well
                    if self._closed:
                        return
                dst.sendall(data)
        except OSError:
            pass
        for sock in (src, dst):
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()

    def cut(self):
        """Severs every connection through the proxy and refuses new ones."""
        with self._lock:
            self._cut = True
            socks, self._open = self._open, []
        for sock in socks:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()

    def stall(self, up=True, down=True):
        """Stops forwarding client -> broker (up) and/or broker -> client (down) without closing
        anything: TCP and MQTT see nothing wrong until a keepalive runs out."""
        for name, stop in (("up", up), ("down", down)):
            if stop:
                self._flowing[name].clear()

    def resume(self):
        for event in self._flowing.values():
            event.set()

    def heal(self):
        with self._lock:
            self._cut = False

    def close(self):
        self._closed = True
        self.resume()
        self.cut()
        self._server.close()
