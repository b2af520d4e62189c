# USB: dummy_hcd is a virtual host controller wired to a virtual device
# controller (UDC "dummy_udc.0"); a configfs gadget on it carrying Orbbec's ids
# 2bc5:0401 appears on the host side as an "Orbbec Astra". Its one function is
# a CDC ACM serial port (usb_f_acm): a gadget needs at least one, and nothing
# on the host side claims it. The tests bind and unbind the gadget themselves
# by writing its UDC file (hot-plug arrival and removal).
suite_targets=(test_usb_gadget test_usb_host)
suite_modules=(dummy_hcd libcomposite usb_f_acm)
# configfs is a module in Debian's arm64 kernel (libcomposite pulls it in), so
# the harness's early mount of /sys/kernel/config did nothing: mount it here.
suite_init='
grep -q " /sys/kernel/config " /proc/mounts || mount -t configfs configfs /sys/kernel/config
g=/sys/kernel/config/usb_gadget/fovea
mkdir -p $g/strings/0x409 $g/configs/c.1/strings/0x409 $g/functions/acm.usb0
echo 0x2bc5 > $g/idVendor
echo 0x0401 > $g/idProduct
echo 0x0200 > $g/bcdUSB
echo FOVEA0401 > $g/strings/0x409/serialnumber
echo "Orbbec (fovea test gadget)" > $g/strings/0x409/manufacturer
echo "Astra" > $g/strings/0x409/product
echo "fovea test" > $g/configs/c.1/strings/0x409/configuration
ln -s $g/functions/acm.usb0 $g/configs/c.1/
ls /sys/class/udc | head -n 1 > $g/UDC
sleep 1
echo "FOVEA-VM: usb gadget on $(cat $g/UDC): $(ls /sys/bus/usb/devices | tr "\n" " ")"
'
suite_env=(FOVEA_USB_GADGET_DIR=/sys/kernel/config/usb_gadget/fovea FOVEA_USB_GADGET_SERIAL=FOVEA0401)
suite_may_skip=0
