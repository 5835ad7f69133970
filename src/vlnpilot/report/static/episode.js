
(function(){
  var root=document.documentElement; root.classList.remove('no-js'); root.classList.add('js');
  var steps=[].slice.call(document.querySelectorAll('.step'));
  if(!steps.length) return;
  var chips=[].slice.call(document.querySelectorAll('.strip button'));
  var rows=[].slice.call(document.querySelectorAll('.steps tr[data-index]'));
  var player=document.getElementById('player'), slider=document.getElementById('slider');
  var pos=document.getElementById('position'), cursor=document.getElementById('cursor');
  var cur=0, movers=document.getElementById('movers');
  function placeMovers(json){ /* issue 24: a dot per person or pet where it was at this step */
    while(movers.firstChild) movers.removeChild(movers.firstChild);
    var dots=[]; try{ dots=JSON.parse(json||'[]'); }catch(e){}
    dots.forEach(function(d){ var el=document.createElement('div');
      el.className='mover '+(d.kind==='pet'?'pet':'person'); el.title=d.name||'';
      el.style.left=d.x+'%'; el.style.top=d.y+'%'; movers.appendChild(el); });
  }
  function mark(list,i,on){ if(list[i]) list[i].classList.toggle('current',on); }
  function show(i,updateHash){
    i=Math.max(0,Math.min(steps.length-1,i|0));
    [steps,chips,rows].forEach(function(l){mark(l,cur,false);mark(l,i,true);});
    cur=i; player.setAttribute('data-current',String(i)); slider.value=String(i);
    var s=steps[i]; pos.textContent=s.getAttribute('data-label')+' of '+steps.length;
    if(cursor){
      var x=s.getAttribute('data-x'), y=s.getAttribute('data-y');
      if(x!==null&&y!==null){ cursor.style.left=x+'%'; cursor.style.top=y+'%';
        cursor.style.setProperty('--yaw',(-parseFloat(s.getAttribute('data-yaw')||'0'))+'deg'); cursor.hidden=false; }
      else { cursor.hidden=true; }
    }
    if(movers){ placeMovers(s.getAttribute('data-movers')); }
    if(updateHash){ try{ history.replaceState(null,'','#'+s.id); }catch(e){} }
  }
  document.addEventListener('keydown',function(e){
    if(e.altKey||e.ctrlKey||e.metaKey||e.shiftKey) return;
    var t=e.target, tag=t&&t.tagName;
    if(tag==='TEXTAREA'||tag==='SELECT'||(tag==='INPUT'&&t.type!=='range')||t===slider) return;
    var k=e.key, n=null;
    if(k==='ArrowRight') n=cur+1; else if(k==='ArrowLeft') n=cur-1;
    else if(k==='Home') n=0; else if(k==='End') n=steps.length-1;
    if(n===null) return;
    e.preventDefault(); show(n,true);
  });
  slider.addEventListener('input',function(){ show(parseInt(slider.value,10),true); });
  document.getElementById('prev').addEventListener('click',function(){ show(cur-1,true); });
  document.getElementById('next').addEventListener('click',function(){ show(cur+1,true); });
  document.getElementById('first').addEventListener('click',function(){ show(0,true); });
  document.getElementById('last').addEventListener('click',function(){ show(steps.length-1,true); });
  chips.forEach(function(c,i){ c.addEventListener('click',function(){ show(i,true); }); });
  rows.forEach(function(r){ r.addEventListener('click',function(){
    show(parseInt(r.getAttribute('data-index'),10),true);
    player.scrollIntoView({behavior:'smooth',block:'start'}); }); });
  var start=0, h=decodeURIComponent(location.hash.slice(1));
  steps.forEach(function(s,i){ if(s.id===h) start=i; });
  show(start,false);
})();
