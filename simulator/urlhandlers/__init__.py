"""pyserial URL handlers of impactlab (``sim://``).

``acquisition.urls.register_url_handlers()`` (through the ``sim`` door of ``simulator.doors``) appends this package to
``serial.protocol_handler_packages``; pyserial then imports ``protocol_<scheme>`` from here.
Nothing happens at import time.
"""
