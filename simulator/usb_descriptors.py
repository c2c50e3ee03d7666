"""The USB descriptors of the simulated analyser (device, configuration, interface, bulk endpoints)
and its identity on the bus: pid.codes test VID/PID, one vendor-specific bulk-only interface."""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import ClassVar

import usb.util

__all__ = ["SIM_VID", "SIM_PID", "EP_OUT", "EP_IN", "MAX_PACKET", "INTERFACE_CLASS", "INTERFACE_SUBCLASS",
           "INTERFACE_PROTOCOL", "CONFIG_VALUE", "LANGID_EN_US", "DeviceDescriptor", "ConfigurationDescriptor",
           "InterfaceDescriptor", "EndpointDescriptor"]

#: pid.codes vendor ID and its test product ID
SIM_VID = 0x1209
SIM_PID = 0x0001
EP_OUT = 0x01
EP_IN = 0x81
MAX_PACKET = 512
INTERFACE_CLASS = 0xFF
INTERFACE_SUBCLASS = 0x06
INTERFACE_PROTOCOL = 0x50
CONFIG_VALUE = 1
LANGID_EN_US = 0x0409


# plain attribute bags, as pyusb's _set_attr reads them
class _Packed:
    """A USB descriptor laid out by ``_FORMAT`` from the attributes named in ``_FIELDS``."""

    _FORMAT: ClassVar[str]
    _FIELDS: ClassVar[tuple[str, ...]]

    def pack(self) -> bytes:
        return struct.pack(self._FORMAT, *(getattr(self, name) for name in self._FIELDS))


@dataclass
class DeviceDescriptor(_Packed):
    idVendor: int
    idProduct: int
    bus: int
    address: int
    port_number: int
    port_numbers: tuple
    speed: int = usb.util.SPEED_HIGH
    bLength: int = 18
    bDescriptorType: int = usb.util.DESC_TYPE_DEVICE
    bcdUSB: int = 0x0200
    bDeviceClass: int = 0x00  # class defined by the interface
    bDeviceSubClass: int = 0x00
    bDeviceProtocol: int = 0x00
    bMaxPacketSize0: int = 64
    bcdDevice: int = 0x0100
    iManufacturer: int = 1
    iProduct: int = 2
    iSerialNumber: int = 3
    bNumConfigurations: int = 1
    extra_descriptors: list = field(default_factory=list)

    _FORMAT: ClassVar[str] = "<BBHBBBBHHHBBBB"
    _FIELDS: ClassVar[tuple[str, ...]] = (
        "bLength", "bDescriptorType", "bcdUSB", "bDeviceClass", "bDeviceSubClass",
        "bDeviceProtocol", "bMaxPacketSize0", "idVendor", "idProduct", "bcdDevice", "iManufacturer",
        "iProduct", "iSerialNumber", "bNumConfigurations")


@dataclass
class ConfigurationDescriptor(_Packed):
    bLength: int = 9
    bDescriptorType: int = usb.util.DESC_TYPE_CONFIG
    wTotalLength: int = 9 + 9 + 7 + 7
    bNumInterfaces: int = 1
    bConfigurationValue: int = CONFIG_VALUE
    iConfiguration: int = 0
    bmAttributes: int = 0xC0  # self powered
    bMaxPower: int = 50  # 100 mA in 2 mA units
    extra_descriptors: list = field(default_factory=list)

    _FORMAT: ClassVar[str] = "<BBHBBBBB"
    _FIELDS: ClassVar[tuple[str, ...]] = (
        "bLength", "bDescriptorType", "wTotalLength", "bNumInterfaces", "bConfigurationValue",
        "iConfiguration", "bmAttributes", "bMaxPower")


@dataclass
class InterfaceDescriptor(_Packed):
    bLength: int = 9
    bDescriptorType: int = usb.util.DESC_TYPE_INTERFACE
    bInterfaceNumber: int = 0
    bAlternateSetting: int = 0
    bNumEndpoints: int = 2
    bInterfaceClass: int = INTERFACE_CLASS
    bInterfaceSubClass: int = INTERFACE_SUBCLASS
    bInterfaceProtocol: int = INTERFACE_PROTOCOL
    iInterface: int = 0
    extra_descriptors: list = field(default_factory=list)

    _FORMAT: ClassVar[str] = "<BBBBBBBBB"
    _FIELDS: ClassVar[tuple[str, ...]] = (
        "bLength", "bDescriptorType", "bInterfaceNumber", "bAlternateSetting", "bNumEndpoints",
        "bInterfaceClass", "bInterfaceSubClass", "bInterfaceProtocol", "iInterface")


@dataclass
class EndpointDescriptor(_Packed):
    bEndpointAddress: int
    bLength: int = 7
    bDescriptorType: int = usb.util.DESC_TYPE_ENDPOINT
    bmAttributes: int = usb.util.ENDPOINT_TYPE_BULK
    wMaxPacketSize: int = MAX_PACKET
    bInterval: int = 0
    bRefresh: int = 0
    bSynchAddress: int = 0
    extra_descriptors: list = field(default_factory=list)

    _FORMAT: ClassVar[str] = "<BBBBHB"
    _FIELDS: ClassVar[tuple[str, ...]] = (
        "bLength", "bDescriptorType", "bEndpointAddress", "bmAttributes", "wMaxPacketSize",
        "bInterval")
