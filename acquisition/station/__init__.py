"""The operator's capture station in the browser (``python -m acquisition station``).

``engine``: the capture session (the one loop of ``acquisition.session``) steered by page actions;
``state``: the server-held session state and the control lease; ``payloads``: plot data as plain
dicts; ``server``: the token-guarded HTTP/JSON/server-sent-events face; ``static/``: the page.
"""
