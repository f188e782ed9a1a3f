"""``stickslip serve``: one process that owns the rig, a web page to drive it live, an API for every other client.

An optional part of stickslip (``pip install 'stickslip[serve]'``: FastAPI, uvicorn,
websockets). The pieces, each with one job (docs/serve.md):

* :mod:`.room`      the control room: owns the controller, the store and the calibration;
  each verb calls one library procedure (the CLI's); one motion at a time; STOP
* :mod:`.owned`     the controller and the store as the procedures see them when the
  server holds them
* :mod:`.pad`       the jog pad: held directions and keep-alives in, key names out, the
  dead man's switch
* :mod:`.security`  the bound address, the token, the origin of a request
* :mod:`.camera`    the camera panel's seam (a frame and the tip's pixel position)
* :mod:`.app`       the HTTP API, the live WebSocket and the page (``static/``)
* :mod:`.run`       starting it all (what ``stickslip serve`` calls)

Nothing below this package imports it; the command line imports it only when ``serve``
runs.
"""
