"""``glsynth view``: an interactive preview in the browser. One render thread owns the one GL
context and serves every open page over a websocket (server.py); messages are checked in
protocol.py, pass images made in frames.py, the scene opened and relit in scene.py, pixels
picked in pick.py, and render requests scheduled in worker.py."""
